"""A scenario's ``[layers]`` table: any level of the app's stack, replaced by a class path.

An application that names its levels (``stack``, one
:class:`~cas_async.scenario.LayerSlot` per level, top first) lets a scenario put a
class of its own in place of any of them::

    [layers]
    task = "my_package.tasks.PatientTask"     # a level by name ...
    2 = "my_package.tasks:CarefulMeeting"     # ... or by index (0 is the top)

:func:`layer_classes` checks the table before anything starts and reports every
problem at once, each under its key (``layers.task``):

* the app declares a ``stack`` (else its levels cannot be replaced), and its ``messages``;
* each key names one level, by name or by an index from 0 to the height minus 1, and
  no level is named twice (once by name and once by index, say);
* each value is a class path, ``package.module.Class`` or ``package.module:Class``
  (``package.module:Outer.Inner`` for a nested class), whose module imports (a
  package next to the scenario file is found, as the app is) and holds that class;
* the class subclasses :class:`~cas_async.Layer` and the level's ``base`` (the app
  builds the level as it builds the base: same constructor, same role), and is not
  abstract;
* each of its hooks can be called as the runtime calls :class:`~cas_async.Layer`'s
  (``async def handle_msg(self, msg)``: async where Layer's is, taking its
  arguments); a robot checks every layer's hooks too, when it is built;
* the class leaves the stack's message set (``app.messages``) as it is: robots
  agree on message types by that set, so a replacement may use only its messages.
  The messages nested in their fields count as theirs (they travel inside them).
  Refused are the :class:`~cas_async.Message` classes defined in the modules of the
  replacement's own classes (its MRO down to, not including, the level's base and
  the base's own ancestors) or inside those classes, and the ones their methods
  name: each function's global names (nested functions, lambdas and comprehensions
  included) and its closure.

The message check reads code, so it has limits: a message reached through an
attribute chain (``messages.Shout(...)``, ``self.kind_of_message``), made by a
helper defined elsewhere, or looked up dynamically is not seen (sent to another
robot, the robot's codec then refuses it: "not among the messages this robot's stack
accepts"); and an attribute named like a module-level message class it does not
refer to is taken for it.

The number of levels cannot change: each key replaces one level by one class.
"""

from __future__ import annotations

import difflib
import functools
import importlib
import importlib.util
import inspect
import re
import sys
import typing
from collections.abc import Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from types import CodeType, FunctionType
from typing import Any, Final, TypeGuard

from ..._core._hooks import hook_problems
from ..._core._layer import Layer
from ..._core._robot import Robot
from ..._errors import ConfigurationError
from ..._wire._message import Message
from ._app import LayerSlot
from ._config import show

__all__ = ["check_built", "importable_from", "layer_classes"]

_CLASS_PATH: Final = re.compile(
    r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*(:[A-Za-z_]\w*(\.[A-Za-z_]\w*)*|\.[A-Za-z_]\w*)"
)
_INDEX: Final = re.compile(r"[+-]?\d+")
_EXPECTED: Final = 'a class path such as "package.module.Class" or "package.module:Class"'
_MISSING: Final = object()

_Problems = list[tuple[str, str]]


def importable_from(path: Path, module_name: str) -> None:
    """Lets a package that ships next to its scenarios be imported from any directory.

    When ``module_name``'s top package is not importable, the nearest directory
    above the scenario file ``path`` that holds it is put on ``sys.path`` (the app
    of a repository's ``apps/x/scenarios/y.toml``, or a user's layers beside their
    scenario, are found whatever the working directory).
    """
    top = module_name.split(".")[0]
    if importlib.util.find_spec(top) is not None:
        return
    for folder in path.resolve().parents:
        if (folder / top / "__init__.py").is_file() or (folder / f"{top}.py").is_file():
            sys.path.append(str(folder))
            return


def layer_classes(
    table: object, app: object, problems: _Problems, path: Path | None = None
) -> dict[str, type[Layer]]:
    """The classes a ``[layers]`` table puts in place of the app's, by slot name.

    Args:
        table: the scenario's ``layers`` value (``None`` when absent).
        app: the application, whose optional ``stack`` and ``messages`` are read.
        problems: where each problem is added, as ``(key, message)``.
        path: the scenario file, to find a package next to it (see
            :func:`importable_from`).

    Returns:
        The valid replacements; every invalid one is a problem instead.
    """
    if table is None:
        return {}
    if not isinstance(table, dict):
        problems.append(("layers", f"expected a table of level = class path, got {show(table)}"))
        return {}
    if not table:
        return {}
    stack: Sequence[LayerSlot[Any]] = tuple(getattr(app, "stack", None) or ())
    name = getattr(app, "name", "the app")
    if not stack:
        problems.append(
            (
                "layers",
                f"{name}'s levels cannot be replaced: the app declares no stack "
                "(a LayerSlot per level, top first)",
            )
        )
        return {}
    messages = getattr(app, "messages", None)
    if messages is None:
        problems.append(
            (
                "layers",
                f"{name} declares a stack but no messages: a replacement cannot be "
                "checked against the stack's message set",
            )
        )
        return {}
    allowed = _with_nested(messages)
    chosen: dict[str, type[Layer]] = {}
    named_by: dict[str, str] = {}  # slot name -> the key that named it first
    for key, value in table.items():
        where = f"layers.{key}"
        level = _level(str(key), stack, where, problems)
        if level is None:
            continue
        index, slot = level
        if slot.name in named_by:
            problems.append(
                (
                    where,
                    f"names level {slot.name} ({index}) again: "
                    f"layers.{named_by[slot.name]} already replaces it",
                )
            )
            continue
        named_by[slot.name] = str(key)
        found = _layer_class(value, slot, allowed, where, problems, path)
        if found is not None:
            chosen[slot.name] = found
    return chosen


def _level(
    key: str, stack: Sequence[LayerSlot[Any]], where: str, problems: _Problems
) -> tuple[int, LayerSlot[Any]] | None:
    """The level ``key`` names, by name or index, or ``None`` with the problem added."""
    for index, slot in enumerate(stack):
        if slot.name == key:
            return index, slot
    levels = ", ".join(f"{slot.name} ({index})" for index, slot in enumerate(stack))
    if _INDEX.fullmatch(key):
        index = int(key)
        if 0 <= index < len(stack):
            return index, stack[index]
        problems.append(
            (
                where,
                f"no level {index}: the stack has {len(stack)} levels, "
                f"0 to {len(stack) - 1} ({levels})",
            )
        )
        return None
    close = difflib.get_close_matches(key, [slot.name for slot in stack], n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    problems.append((where, f"no level named {key!r} ({hint}the levels are {levels})"))
    return None


def _layer_class(
    value: object,
    slot: LayerSlot[Any],
    allowed: frozenset[type[Message]],
    where: str,
    problems: _Problems,
    path: Path | None,
) -> type[Layer] | None:
    """The class ``value`` names, if it may stand at ``slot``; else ``None``, problem added."""
    if not isinstance(value, str) or not _CLASS_PATH.fullmatch(value):
        problems.append((where, f"expected {_EXPECTED}, got {show(value)}"))
        return None
    if ":" in value:
        module_name, _, attribute = value.partition(":")
    else:
        module_name, _, attribute = value.rpartition(".")
    if path is not None:
        importable_from(path, module_name)
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        problems.append((where, f"cannot import {module_name!r}: {error}"))
        return None
    except Exception as error:  # the user's module raised: say what, it is theirs to fix
        problems.append(
            (where, f"cannot import {module_name!r}: it raised {type(error).__name__}: {error}")
        )
        return None
    found: Any = module
    for part in attribute.split("."):
        found = getattr(found, part, _MISSING)
        if found is _MISSING:
            problems.append((where, f"module {module_name!r} has no attribute {attribute!r}"))
            return None
    if not isinstance(found, type):
        problems.append((where, f"expected a class, got {value!r}, a {type(found).__name__}"))
        return None
    base = _name(slot.base)
    if not issubclass(found, Layer):
        problems.append((where, f"{value} is not a layer: it does not subclass cas_async.Layer"))
    elif not issubclass(found, slot.base):
        problems.append(
            (
                where,
                f"{value} does not subclass {base}: the {slot.name} level is built as "
                f"{slot.base.__name__} is built (same constructor, same role)",
            )
        )
    elif inspect.isabstract(found):
        missing = ", ".join(sorted(getattr(found, "__abstractmethods__", ())))
        problems.append((where, f"{value} is abstract (it lacks {missing}): it cannot be built"))
    elif hooks := hook_problems(found):
        problems.extend((where, f"{value}.{problem}") for problem in hooks)
    else:
        foreign = _foreign_messages(found, slot.base, allowed)
        if not foreign:
            return found
        brought = "; ".join(f"{_name(cls)} ({how})" for cls, how in foreign.items())
        problems.append(
            (
                where,
                f"{value} would change the stack's message set: it brings {brought}, "
                "not among the app's messages (a replacement may use only those)",
            )
        )
    return None


def _name(cls: type[Any]) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def _own_classes(cls: type[Any], base: type[Any]) -> list[type[Any]]:
    """``cls``'s MRO without ``base`` and its ancestors: the classes the replacement adds."""
    below = set(base.__mro__)
    return [klass for klass in cls.__mro__ if klass not in below]


def _is_message(candidate: object) -> TypeGuard[type[Message]]:
    return (
        isinstance(candidate, type) and issubclass(candidate, Message) and candidate is not Message
    )


def _with_nested(messages: Iterable[type[Message]]) -> frozenset[type[Message]]:
    """``messages`` and the messages their fields nest, however deep."""
    found: set[type[Message]] = set()
    todo = list(messages)
    while todo:
        cls = todo.pop()
        if cls in found:
            continue
        found.add(cls)
        try:
            hints = typing.get_type_hints(cls)
        except Exception:  # an annotation that does not resolve: nothing nested is known
            continue
        todo.extend(nested for hint in hints.values() for nested in _messages_in(hint))
    return frozenset(found)


def _messages_in(hint: object) -> Iterator[type[Message]]:
    """The message classes a type annotation names (``list[Point] | None``: ``Point``)."""
    if _is_message(hint):
        yield hint
    for argument in typing.get_args(hint):
        yield from _messages_in(argument)


def _foreign_messages(
    cls: type[Any], base: type[Any], allowed: frozenset[type[Message]]
) -> dict[type[Message], str]:
    """Message classes outside ``allowed`` that ``cls`` defines or names, with where from."""
    foreign: dict[type[Message], str] = {}

    def note(candidate: object, how: str) -> None:
        if _is_message(candidate) and candidate not in allowed and candidate not in foreign:
            foreign[candidate] = how

    own = _own_classes(cls, base)
    for klass in own:
        module = sys.modules.get(klass.__module__)
        for member in vars(module).values() if module is not None else ():
            if _is_message(member) and member.__module__ == klass.__module__:
                note(member, f"defined in {klass.__module__}")
        for member in vars(klass).values():
            note(member, f"defined in {klass.__qualname__}")
    for klass in own:
        for attribute, function in _functions(klass):
            for candidate in _referred(function):
                note(candidate, f"used by {klass.__qualname__}.{attribute}")
    return foreign


def _functions(klass: type[Any]) -> Iterator[tuple[str, FunctionType]]:
    """Every function ``klass`` itself defines, with the attribute that holds it."""
    for attribute, member in vars(klass).items():
        if isinstance(member, staticmethod | classmethod):
            member = member.__func__
        if isinstance(member, functools.cached_property):
            member = member.func
        if isinstance(member, property):
            parts: tuple[object, ...] = (member.fget, member.fset, member.fdel)
        else:
            parts = (member,)
        for part in parts:
            # A decorator's wrapper, then what it wraps (functools.wraps keeps the chain).
            while isinstance(part, FunctionType):
                yield attribute, part
                part = getattr(part, "__wrapped__", None)


def _referred(function: FunctionType) -> Iterator[object]:
    """What ``function``'s global names and closure cells hold (attribute names: see the module)."""
    namespace: Mapping[str, Any] = function.__globals__
    for name in _names(function.__code__):
        if name in namespace:
            yield namespace[name]
    for cell in function.__closure__ or ():
        try:
            yield cell.cell_contents
        except ValueError:  # an empty cell: the variable was never set
            continue


def _names(code: CodeType) -> Iterator[str]:
    """``code``'s names and those of the code objects nested in it."""
    yield from code.co_names
    for constant in code.co_consts:
        if isinstance(constant, CodeType):
            yield from _names(constant)


def check_built(
    stack: Sequence[LayerSlot[Any]], layers: Mapping[str, type[Layer]], robots: Iterable[Robot]
) -> None:
    """Every robot has the stack's height and, at each replaced level, the scenario's class.

    Raises:
        ConfigurationError: the app built a robot without ``setup.layer(...)``.
    """
    if not layers:
        return
    names = [slot.name for slot in stack]
    for robot in robots:
        built = robot.layers
        if len(built) != len(names):
            raise ConfigurationError(
                f"layers: robot {robot.robot_id} was built with {len(built)} layers, "
                f"but the app's stack names {len(names)}"
            )
        for name, cls in layers.items():
            level = names.index(name)
            if not isinstance(built[level], cls):
                raise ConfigurationError(
                    f"layers.{name}: robot {robot.robot_id}'s level {level} was built as "
                    f"{type(built[level]).__qualname__}, not {cls.__qualname__}: "
                    "the app must build each level with setup.layer(SLOT)"
                )
