"""The command line (internal): ``python -m cas_async COMMAND``, the top floor.

``_main`` dispatches to one module per command; ``_parser`` holds their arguments;
``_interrupts`` decides what SIGINT and SIGTERM do at each moment of a command,
``_pipes`` what output into a closed pipe does, and ``_shadow`` explains a clone's
folder taken for the package. Nothing in the library imports this package: only
``cas_async.__main__`` does.
"""

__all__: list[str] = []
