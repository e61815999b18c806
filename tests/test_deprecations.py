"""The public API keeps its promises: every name of the last release still imports.

``public_names_0_1_0.json`` holds every name the faces of 0.1.0 exported (as the
release was, before and after messages became msgspec Structs). Each still imports
from where it did: silently while it is public, or with one ``DeprecationWarning``
that names what replaces it (``CHANGELOG.md`` lists them).
"""

from __future__ import annotations

import ast
import importlib
import json
import types
import warnings
from pathlib import Path
from typing import Annotated, Final

import msgspec
import pytest

import cas_async
from cas_async import Message

RELEASE: Final = json.loads((Path(__file__).with_name("public_names_0_1_0.json")).read_text())
NAMES: Final = [(face, name) for face, names in sorted(RELEASE.items()) for name in names]


def _optional(face: str) -> None:
    extra = {"cas_async.rl": "pettingzoo", "cas_async.ros": "rosbags"}.get(face)
    if extra is not None:
        pytest.importorskip(extra, reason=f"{face} needs its extra")


@pytest.mark.parametrize(("face", "name"), NAMES, ids=[f"{f}.{n}" for f, n in NAMES])
def test_every_name_of_the_last_release_imports_or_warns_naming_its_heir(
    face: str, name: str
) -> None:
    _optional(face)
    module = importlib.import_module(face)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        value = getattr(module, name)
    if name in module.__all__:
        assert caught == []
        return
    (warning,) = caught
    assert warning.category is DeprecationWarning
    text = str(warning.message)
    assert text.startswith(f"{face}.{name} is deprecated and will be removed in 0.3.0: ")
    assert warning.filename == __file__  # it points at the user's line
    heir = text.rsplit("use ", 1)[-1]
    if heir.startswith("cas_async.") and " " not in heir:
        where, _, new = heir.rpartition(".")
        assert getattr(importlib.import_module(where), new) is value


def test_from_face_import_a_moved_name_warns_once() -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        from cas_async.scenario import Trace  # noqa: F401
    assert [str(w.message).split(" is ")[0] for w in caught] == ["cas_async.scenario.Trace"]


def test_a_name_no_release_had_is_an_attribute_error() -> None:
    with pytest.raises(AttributeError, match="module 'cas_async' has no attribute 'Bound'"):
        cas_async.Bound  # noqa: B018
    with pytest.raises(ImportError):
        from cas_async.scenario import Sweep  # type: ignore[attr-defined]  # noqa: F401


def test_old_bounds_still_bound_a_message() -> None:
    with pytest.warns(DeprecationWarning, match=r"msgspec\.Meta"):
        bounds = cas_async.Bounds  # type: ignore[attr-defined]

    # As an app of 0.1.0 declared it (evaluated annotations: this module defers its own).
    fields = {
        "speed": Annotated[float, bounds(ge=0, finite=True)],
        "seats": Annotated[int, bounds(ge=1, le=8)],
    }
    Speed = types.new_class(
        "Speed", (Message,), exec_body=lambda ns: ns.update(__annotations__=fields)
    )
    decoder = msgspec.msgpack.Decoder(Speed)
    good = Speed(speed=1.5, seats=2)
    assert decoder.decode(msgspec.msgpack.encode(good)).seats == 2
    for bad in (Speed(speed=-1.0, seats=2), Speed(speed=float("inf"), seats=2), Speed(1.0, 9)):
        with pytest.raises(msgspec.ValidationError):
            decoder.decode(msgspec.msgpack.encode(bad))


def test_old_spec_of_describes_a_message_from_its_class() -> None:
    class Ping(Message):
        n: int
        note: str = ""

    with pytest.warns(DeprecationWarning, match="message_fields"):
        spec_of = cas_async.spec_of  # type: ignore[attr-defined]
    spec = spec_of(Ping)
    assert (spec.cls, spec.field_names, spec.field_types) == (Ping, ("n", "note"), (int, str))
    assert spec.type_id == Ping.__struct_config__.tag


def _type_checking_imports() -> dict[str, str]:
    """The names the root face's ``if TYPE_CHECKING:`` block imports, and from where."""
    tree = ast.parse(Path(cas_async.__file__).read_text())
    block = next(
        node
        for node in tree.body
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
    )
    return {
        alias.name: "." * node.level + (node.module or "")
        for node in block.body
        if isinstance(node, ast.ImportFrom)
        for alias in node.names
    }


def test_the_root_face_loads_each_name_from_where_type_checkers_see_it() -> None:
    homes = vars(cas_async)["_HOMES"]
    assert _type_checking_imports() == homes
    assert sorted(homes) == cas_async.__all__


def test_the_version_is_the_changelogs_newest_release() -> None:
    import tomllib

    import cas_async

    root = Path(__file__).resolve().parent.parent
    project = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    newest = next(
        line
        for line in (root / "CHANGELOG.md").read_text(encoding="utf-8").splitlines()
        if line.startswith("## [")
    )
    assert project["project"]["version"] == cas_async.__version__
    assert newest.startswith(f"## [{cas_async.__version__}] - ")
