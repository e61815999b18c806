"""What an application's world holds besides its robots: the static scene the views draw.

An application declares its scene once, when it builds the mission
(``Mission(..., scene=Scene([...]))``): the live view, the replay of a run
directory and the MCAP export draw it under the robots. It is static: it is
drawn as declared for the whole run. Things that move are robots (their
positions are the trace's); what a robot carries is drawn on the robot.

Four shapes, in world coordinates (the world's corner at ``(0, 0)``):

* :class:`Disc`: a round area (a zone, a station's pad);
* :class:`Rect`: a rectangle about its centre, turned by ``angle`` (an object);
* :class:`Polyline`: an open line through points (a lane, a route);
* :class:`Spot`: a point (a drop spot, a landmark).

Each has a ``label`` drawn beside it and a ``kind``: the views give each kind
one colour, the same as a robot group of that name (a Generator's pad is the
Generators' colour), unless :attr:`Scene.colors` names one.

A scene is written as JSON into every run directory (``scene.json``, see
:meth:`Scene.to_json` and :meth:`Scene.from_json`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, TypeAlias

__all__ = ["Disc", "Polyline", "Rect", "Scene", "Shape", "Spot"]

_COLOR: Final = re.compile(r"#[0-9a-fA-F]{6}")
_LABEL_LIMIT: Final = 200


def _finite(owner: str, **values: float) -> None:
    for name, value in values.items():
        if (
            not isinstance(value, int | float)
            or isinstance(value, bool)
            or not math.isfinite(value)
        ):
            raise ValueError(f"{owner}: {name} must be a finite number, got {value!r}")


def _text(owner: str, **values: str) -> None:
    for name, value in values.items():
        if not isinstance(value, str) or len(value) > _LABEL_LIMIT:
            raise ValueError(
                f"{owner}: {name} must be a string of at most {_LABEL_LIMIT} characters, "
                f"got {value!r:.60}"
            )


@dataclass(frozen=True, slots=True)
class Disc:
    """A round area: centre ``(x, y)`` and ``radius`` (a zone, a station's pad)."""

    x: float
    y: float
    radius: float
    label: str = ""
    kind: str = ""

    def __post_init__(self) -> None:
        _finite("Disc", x=self.x, y=self.y, radius=self.radius)
        if self.radius <= 0:
            raise ValueError(f"Disc: radius must be above 0, got {self.radius!r}")
        _text("Disc", label=self.label, kind=self.kind)


@dataclass(frozen=True, slots=True)
class Rect:
    """A rectangle of ``width`` by ``height`` about its centre ``(x, y)``, turned by ``angle``.

    ``angle`` is in radians, counter-clockwise, as a robot's heading.
    """

    x: float
    y: float
    width: float
    height: float
    angle: float = 0.0
    label: str = ""
    kind: str = ""

    def __post_init__(self) -> None:
        _finite("Rect", x=self.x, y=self.y, width=self.width, height=self.height, angle=self.angle)
        if self.width <= 0 or self.height <= 0:
            raise ValueError(
                f"Rect: width and height must be above 0, got {self.width!r} by {self.height!r}"
            )
        _text("Rect", label=self.label, kind=self.kind)


@dataclass(frozen=True, slots=True)
class Polyline:
    """An open line through ``points`` (at least two ``(x, y)``): a lane, a route."""

    points: tuple[tuple[float, float], ...]
    label: str = ""
    kind: str = ""

    def __post_init__(self) -> None:
        points = tuple((float(x), float(y)) for x, y in self.points)
        if len(points) < 2:
            raise ValueError(f"Polyline: needs at least two points, got {len(points)}")
        for index, (x, y) in enumerate(points):
            _finite(f"Polyline point {index}", x=x, y=y)
        object.__setattr__(self, "points", points)
        _text("Polyline", label=self.label, kind=self.kind)


@dataclass(frozen=True, slots=True)
class Spot:
    """A point ``(x, y)``: a drop spot, a landmark."""

    x: float
    y: float
    label: str = ""
    kind: str = ""

    def __post_init__(self) -> None:
        _finite("Spot", x=self.x, y=self.y)
        _text("Spot", label=self.label, kind=self.kind)


Shape: TypeAlias = Disc | Rect | Polyline | Spot
"""One shape of a :class:`Scene`."""

_NAMES: Final[dict[type[Any], str]] = {
    Disc: "disc",
    Rect: "rect",
    Polyline: "polyline",
    Spot: "spot",
}


@dataclass(frozen=True, slots=True)
class Scene:
    """The static scene an application declares (see the module docs).

    Attributes:
        shapes: drawn in this order, under the robots.
        colors: a colour (``"#rrggbb"``) for some kinds; the views pick the others.

    Raises:
        ValueError: a shape is not one of the four, or a colour is not ``#rrggbb``.
    """

    shapes: Sequence[Shape] = ()
    colors: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        shapes = tuple(self.shapes)
        for index, shape in enumerate(shapes):
            if type(shape) not in _NAMES:
                raise ValueError(
                    f"Scene: shape {index} is a {type(shape).__name__}, "
                    "expected a Disc, Rect, Polyline or Spot"
                )
        object.__setattr__(self, "shapes", shapes)
        for kind, color in self.colors.items():
            if not isinstance(color, str) or not _COLOR.fullmatch(color):
                raise ValueError(f"Scene: colors[{kind!r}] must be '#rrggbb', got {color!r}")
        object.__setattr__(self, "colors", dict(self.colors))

    @property
    def kinds(self) -> list[str]:
        """Every shape's kind, once each, in the order of first use (empty kinds left out)."""
        return list(dict.fromkeys(shape.kind for shape in self.shapes if shape.kind))

    def to_json(self) -> dict[str, Any]:
        """The scene as plain JSON data (the ``scene`` of ``scene.json`` and the live hello)."""
        return {
            "shapes": [{"shape": _NAMES[type(shape)], **_fields(shape)} for shape in self.shapes],
            "colors": dict(self.colors),
        }

    @classmethod
    def from_json(cls, data: Any, where: str = "scene") -> Scene:
        """Reads what :meth:`to_json` wrote.

        Raises:
            ValueError: naming ``where`` and the key at fault.
        """
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected an object, got {type(data).__name__}")
        shapes = data.get("shapes", [])
        if not isinstance(shapes, list):
            raise ValueError(f"{where}.shapes: expected a list, got {type(shapes).__name__}")
        read: list[Shape] = []
        for index, item in enumerate(shapes):
            at = f"{where}.shapes[{index}]"
            if not isinstance(item, dict):
                raise ValueError(f"{at}: expected an object, got {type(item).__name__}")
            kinds = {name: kind for kind, name in _NAMES.items()}
            kind = kinds.get(item.get("shape"))  # type: ignore[arg-type]
            if kind is None:
                raise ValueError(
                    f"{at}.shape: expected one of {sorted(kinds)}, got {item.get('shape')!r}"
                )
            values = {key: value for key, value in item.items() if key != "shape"}
            try:
                if kind is Polyline and isinstance(values.get("points"), list):
                    values["points"] = tuple(_point(point) for point in values["points"])
                read.append(kind(**values))
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{at}: {exc}") from None
        colors = data.get("colors", {})
        if not isinstance(colors, dict):
            raise ValueError(f"{where}.colors: expected an object, got {type(colors).__name__}")
        try:
            return cls(read, colors)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None


def _point(point: Any) -> tuple[Any, ...]:
    if not isinstance(point, list | tuple):
        raise ValueError(f"Polyline: a point is [x, y], got {point!r:.40}")
    return tuple(point)


def _fields(shape: Shape) -> dict[str, Any]:
    if isinstance(shape, Polyline):
        return {
            "points": [list(point) for point in shape.points],
            "label": shape.label,
            "kind": shape.kind,
        }
    return {name: getattr(shape, name) for name in shape.__dataclass_fields__}
