"""The static scene an application declares: its shapes, their checks, its JSON, its colours."""

from __future__ import annotations

import math
from typing import Any

import pytest

from cas_async.live._protocol import OTHER, PALETTE, colors_for
from cas_async.scenario import Disc, Polyline, Rect, Scene, Spot, load_scenario

from .helpers import BOXES, FIRE


def test_a_scene_survives_its_json() -> None:
    scene = Scene(
        [
            Disc(1.0, 2.0, 0.5, label="pad", kind="station"),
            Rect(3.0, 4.0, 1.0, 2.0, angle=0.5, label="7", kind="object"),
            Polyline([(0, 0), (1, 1), (2, 0)], kind="lane"),
            Spot(5.0, 6.0, kind="spot"),
        ],
        colors={"lane": "#123abc"},
    )
    again = Scene.from_json(scene.to_json())
    assert again == scene
    assert scene.kinds == ["station", "object", "lane", "spot"]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: Disc(0, 0, 0), "radius must be above 0"),
        (lambda: Disc(math.nan, 0, 1), "x must be a finite number"),
        (lambda: Rect(0, 0, 1, -1), "width and height must be above 0"),
        (lambda: Polyline([(0, 0)]), "at least two points"),
        (lambda: Polyline([(0, 0), (math.inf, 1)]), "point 1: x must be a finite number"),
        (lambda: Spot(0, 0, label="x" * 201), "at most 200 characters"),
        (lambda: Scene([Disc(0, 0, 1)], colors={"a": "red"}), "colors\\['a'\\] must be '#rrggbb'"),
        (lambda: Scene(["disc"]), "shape 0 is a str"),  # type: ignore[list-item]
    ],
    ids=["radius", "nan", "size", "points", "inf", "label", "color", "not-a-shape"],
)
def test_a_shape_that_cannot_be_drawn_is_refused(make: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make()


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ([], "scene.json: expected an object"),
        ({"shapes": {}}, "scene.json.shapes: expected a list"),
        ({"shapes": [{"shape": "hexagon"}]}, r"scene.json.shapes\[0\].shape: expected one of"),
        ({"shapes": [{"shape": "disc", "x": 1}]}, r"scene.json.shapes\[0\]: .*radius"),
        ({"shapes": [{"shape": "disc", "x": 1, "y": 1, "radius": -1}]}, "radius must be above"),
    ],
    ids=["not-object", "shapes", "unknown", "missing", "invalid"],
)
def test_a_malformed_scene_file_is_refused_naming_the_key(data: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Scene.from_json(data, "scene.json")


def test_colours_follow_groups_then_kinds_and_a_kind_named_as_a_group_shares_its_colour() -> None:
    scene = Scene([Disc(0, 0, 1, kind="Sink"), Disc(0, 0, 1, kind="zone")], colors={"x": "#000000"})
    colors = colors_for(["Generator", "Sink"], scene)
    assert colors == {
        "x": "#000000",
        "Generator": PALETTE[0],
        "Sink": PALETTE[1],
        "zone": PALETTE[2],
    }
    many = colors_for([f"g{k}" for k in range(len(PALETTE) + 2)], Scene())
    assert list(many.values())[-1] == OTHER


def test_the_fire_brigade_declares_its_stations_and_their_lines() -> None:
    scenario = load_scenario(FIRE / "scale_250.toml")
    config = scenario.config
    stations = config.stations
    generators, sinks = stations.placed(stations.generators), stations.placed(stations.sinks)
    from apps.fire_brigade.scene import brigade_scene

    scene = brigade_scene(generators, sinks)
    discs = [shape for shape in scene.shapes if isinstance(shape, Disc)]
    assert [d.kind for d in discs].count("Generator") == len(generators) == 20
    assert [(d.x, d.y) for d in discs if d.kind == "Sink"] == list(sinks)
    lines = [shape for shape in scene.shapes if isinstance(shape, Polyline)]
    assert len(lines) == len(generators)
    assert all(line.points[0] in generators and line.points[1] in sinks for line in lines)


def test_box_moving_declares_its_objects_zone_and_drop_spots() -> None:
    from apps.box_moving.layout import place_objects
    from apps.box_moving.scene import floor_scene

    scenario = load_scenario(BOXES / "thesis_4_4.toml")
    config = scenario.config
    import numpy as np

    boxes = place_objects(config, np.random.default_rng(1))
    scene = floor_scene(boxes, (config.destination.at, config.destination.radius))
    rects = [shape for shape in scene.shapes if isinstance(shape, Rect)]
    assert [(r.x, r.y, r.width) for r in rects] == [(b.x, b.y, b.size) for b in boxes]
    spots = [shape for shape in scene.shapes if isinstance(shape, Spot)]
    assert [(s.x, s.y) for s in spots] == [b.drop for b in boxes]
    (zone,) = [shape for shape in scene.shapes if isinstance(shape, Disc)]
    assert (zone.x, zone.y, zone.radius) == (*config.destination.at, config.destination.radius)
