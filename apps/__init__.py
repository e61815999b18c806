"""Applications built on cas_async's public API."""
