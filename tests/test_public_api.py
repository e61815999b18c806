"""The public API is chosen on purpose: complete, sorted, and importable."""

from __future__ import annotations

import importlib
import pkgutil
import types

import cas_async
import cas_async.scenario


def test_all_is_sorted_and_unique() -> None:
    assert cas_async.__all__ == sorted(set(cas_async.__all__))
    assert cas_async.scenario.__all__ == sorted(set(cas_async.scenario.__all__))


def test_scenario_names_exist() -> None:
    missing = [name for name in cas_async.scenario.__all__ if not hasattr(cas_async.scenario, name)]
    assert not missing


def test_all_names_exist() -> None:
    missing = [name for name in cas_async.__all__ if not hasattr(cas_async, name)]
    assert not missing


def test_every_public_name_of_every_module_is_exported() -> None:
    """A name a module exports is either re-exported at the top or deliberately internal."""
    internal = {
        # plumbing used between modules, not by applications
        "HEADER_FIELDS",
        "registered",
        "lookup",
        "specs_for",
        "nested_to_wire",
        "FieldType",
        "field_type",
        "nested_message_hook",
        "DropLog",
        "PrefixLogger",
        "logger_for",
        "Channel",
        "DEFAULT_QUEUE_LIMIT",
        "MAX_UDP_PAYLOAD",
        # the stdlib loop's selector: loop_factory() is how applications get it
        "PreciseEpollSelector",
        "precise_selector_available",
        "SocketWire",
        "HEADER_LEN",
        "Compiled",
        "compiled",
        "MIN_DATAGRAM",
        "ReplyOutcome",
        "Unconnected",
        "drop_socket_error",
        "SegmentTable",
        "PendingRequests",
        "Deadlines",
        "undispatchable",
        "Reception",
        "SenderWindows",
        "ReplyCache",
        "WINDOW",
        "FRESH",
        "DUPLICATE",
        "STALE",
        "run_layer",
        "run_loop",
        "slide",
        "Receiver",
        "Requesting",
        "ensure_descriptors",
        "CellGrid",
        "young_generation_for",
        "owned",
    }
    exported = set(cas_async.__all__)
    # Public subpackages with an API of their own (for application authors).
    namespaces = {"cas_async.scenario": set(cas_async.scenario.__all__), "cas_async.cli": {"main"}}
    for info in pkgutil.walk_packages(cas_async.__path__, "cas_async."):
        module = importlib.import_module(info.name)
        assert hasattr(module, "__all__"), f"{info.name} has no __all__"
        public = exported.union(
            *(names for prefix, names in namespaces.items() if info.name.startswith(prefix))
        )
        for name in module.__all__:
            assert name in public or name in internal, (
                f"{info.name}.{name} is neither exported nor internal"
            )
    public_top = {
        name
        for name, value in vars(cas_async).items()
        if not name.startswith("_") and not isinstance(value, types.ModuleType)
    }
    assert public_top == exported


def test_the_package_is_typed() -> None:
    from importlib.resources import files

    assert files("cas_async").joinpath("py.typed").is_file()
