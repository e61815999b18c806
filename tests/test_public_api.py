"""The public API is chosen on purpose: each audience has one face, the rest is internal.

* ``cas_async``: what a layer author (and whoever assembles robots) uses;
* ``cas_async.transport``: what a transport author implements and wraps;
  ``cas_async.transport.zenoh``: Zenoh's transport and the plumbing others build on;
* ``cas_async.sim``: the simulation kit (Environment, kinematics, simulated middleware);
* ``cas_async.scenario``: scenario files and runs, and the contract of an application;
  ``cas_async.scenario.output``: what a run measured and how it is written;
  ``cas_async.scenario.sweeps``: a scenario over a grid of values and seeds;
* ``cas_async.testing``: what a user's test suite uses (with the pytest plugin);
* ``cas_async.live``: watching a run: the live view, replays, MCAP export;
* ``cas_async.ros``: ROS 2 robots over rmw_zenoh (the ``ros`` extra);
* ``cas_async.rl``: a scenario as a learning environment (the ``rl`` extra).

Every other module is internal, and says so with a leading underscore in its path.

Names that are no identifiers (``@py_builtins``, ``@pytest_ar``) are pytest's: it
rewrites the asserts of a plugin's whole distribution, cas_async included since it
ships the ``cas_async_pytest`` plugin.
"""

from __future__ import annotations

import contextlib
import importlib
import pkgutil
import types

import pytest

import cas_async
import cas_async.live
import cas_async.ros
import cas_async.scenario
import cas_async.scenario.output
import cas_async.scenario.sweeps
import cas_async.sim
import cas_async.testing
import cas_async.transport
import cas_async.transport.zenoh

FACES: dict[str, types.ModuleType] = {
    "cas_async": cas_async,
    "cas_async.live": cas_async.live,
    "cas_async.ros": cas_async.ros,
    "cas_async.scenario": cas_async.scenario,
    "cas_async.scenario.output": cas_async.scenario.output,
    "cas_async.scenario.sweeps": cas_async.scenario.sweeps,
    "cas_async.sim": cas_async.sim,
    "cas_async.testing": cas_async.testing,
    "cas_async.transport": cas_async.transport,
    "cas_async.transport.zenoh": cas_async.transport.zenoh,
}
SUBPACKAGES = {"live", "rl", "ros", "scenario", "sim", "testing", "transport"}
EXTRAS = {"cas_async.rl": "rl"}
"""Faces that need an extra: checked where it is installed (CI installs them all)."""
for _face in EXTRAS:
    with contextlib.suppress(ImportError):
        FACES[_face] = importlib.import_module(_face)


def _names(module: types.ModuleType) -> dict[str, object]:
    """The module's names, without pytest's (see the module docs)."""
    return {name: value for name, value in vars(module).items() if name.isidentifier()}


def _modules() -> list[str]:
    """Every module of the package, but those of an extra that is not installed."""
    missing = tuple(face for face in EXTRAS if face not in FACES)
    return [
        info.name
        for info in pkgutil.walk_packages(cas_async.__path__, "cas_async.")
        if not (missing and info.name.startswith(missing))
    ]


def test_every_module_is_a_face_or_marked_internal() -> None:
    public = [
        name
        for name in _modules()
        if name not in FACES
        and not name.endswith(".__main__")
        and not any(part.startswith("_") for part in name.split(".")[1:])
    ]
    assert not public, f"modules neither a face nor internal (name them _module): {public}"


def test_every_module_declares_its_names() -> None:
    missing = [name for name in _modules() if not hasattr(importlib.import_module(name), "__all__")]
    assert not missing


@pytest.mark.parametrize("face", sorted(FACES))
def test_a_face_lists_its_names_sorted_once(face: str) -> None:
    names = FACES[face].__all__
    assert names == sorted(set(names))


@pytest.mark.parametrize("face", sorted(FACES))
def test_a_face_exports_exactly_what_it_lists(face: str) -> None:
    module = FACES[face]
    missing = [name for name in module.__all__ if not hasattr(module, name)]
    assert not missing
    public = {
        name
        for name, value in _names(module).items()
        if not name.startswith("_") and not isinstance(value, types.ModuleType)
    }
    assert public == set(module.__all__)


@pytest.mark.parametrize("face", sorted(FACES))
def test_no_name_of_a_face_is_a_module(face: str) -> None:
    """``cas_async.message`` is the decorator: no module of that name hides behind it."""
    module = FACES[face]
    modules = {
        name
        for name, value in _names(module).items()
        if not name.startswith("_") and isinstance(value, types.ModuleType)
    }
    inner = {name.rpartition(".")[2] for name in FACES if name.rpartition(".")[0] == face}
    assert modules <= (SUBPACKAGES if face == "cas_async" else inner)
    assert not isinstance(cas_async.message, types.ModuleType)


def test_the_package_is_typed() -> None:
    from importlib.resources import files

    assert files("cas_async").joinpath("py.typed").is_file()
