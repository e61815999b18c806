"""Examples of cas_async: each folder (or file) is one, with a README where it has several parts."""

__all__: list[str] = []
