"""Scenario checks that name the key at fault, and the layout of objects and drop spots."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from apps.box_moving import MESSAGES, app
from apps.box_moving.config import BoxMovingConfig, Destination, ObjectSpec, RobotSpec, Scatter
from apps.box_moving.layout import drop_spots, place_objects
from cas_async._wire._message import wire_name
from cas_async.scenario import ScenarioError, load_scenario
from tests.box_moving.helpers import SCENARIOS

WORLD = (12.0, 10.0)
ROBOTS = (RobotSpec(1.0, 2.0, payload=10.0), RobotSpec(1.0, 8.0, payload=6.0))


def problems(config: BoxMovingConfig) -> dict[str, str]:
    with pytest.raises(ScenarioError) as caught:
        app.check(config, WORLD)
    return dict(caught.value.problems)


def objects(*weights: float) -> tuple[ObjectSpec, ...]:
    return tuple(ObjectSpec(2.0 + k, 3.0, weight, 0.5) for k, weight in enumerate(weights))


def test_an_object_no_pair_can_lift_is_refused_by_its_key() -> None:
    found = problems(BoxMovingConfig(robots=ROBOTS, objects=objects(3, 9, 15, 17, 4)))
    assert found == {
        "objects[3].weight": "no two robots can lift 17: the two strongest robots lift 16"
    }


def test_too_small_a_zone_too_high_a_target_and_misplaced_things_are_named() -> None:
    config = BoxMovingConfig(
        robots=(RobotSpec(20.0, 2.0), *ROBOTS),
        objects=(*objects(3, 4), ObjectSpec(9.0, 5.0, 2.0, 0.5), ObjectSpec(11.9, 5.0, 2.0, 0.5)),
        destination=Destination((9.0, 5.0), 0.6),
        scatter=Scatter(count=1, weight=(5.0, 2.0)),
    )
    from dataclasses import replace

    found = problems(replace(config, mission=replace(config.mission, target=9)))
    assert set(found) == {
        "robots[0]",
        "objects[2]",
        "objects[3]",
        "destination.radius",
        "mission.target",
        "scatter.weight",
    }
    assert "lies in the destination zone" in found["objects[2]"]
    assert "holds 1 drop spots, for 5 objects" in found["destination.radius"]


def test_the_shipped_scenarios_load() -> None:
    for path in sorted(SCENARIOS.glob("*.toml")):
        scenario = load_scenario(path)
        assert scenario.app is app
    fixed = load_scenario(SCENARIOS / "thesis_4_4_fixed.toml")
    assert [cls.__name__ for cls in fixed.layers.values()] == ["FixedSideCoordination"]


def test_a_replacement_layer_must_be_a_box_layer(tmp_path: Path) -> None:
    scenario = tmp_path / "bad.toml"
    scenario.write_text(
        f'extends = "{SCENARIOS / "thesis_4_4.toml"}"\n'
        '[layers]\ncoordination = "apps.box_moving.action.Action"\n'
    )
    with pytest.raises(ScenarioError, match=r"layers\.coordination"):
        load_scenario(scenario)


def test_drop_spots_are_distinct_inside_the_zone_nearest_the_centre_first() -> None:
    spots = drop_spots((9.0, 5.0), 2.8, 1.2, 9)
    assert len(set(spots)) == 9
    assert spots[0] == (9.0, 5.0)
    far = [math.dist(spot, (9.0, 5.0)) for spot in spots]
    assert far == sorted(far)
    assert max(far) + 0.6 <= 2.8
    assert all(math.dist(a, b) >= 1.5 - 1e-9 for k, a in enumerate(spots) for b in spots[k + 1 :])
    assert len(drop_spots((9.0, 5.0), 2.8, 1.2, 50)) == 9  # no more fit


def test_scattered_objects_follow_the_seed_and_each_has_its_own_drop_spot() -> None:
    config = BoxMovingConfig(
        robots=ROBOTS,
        objects=objects(3),
        scatter=Scatter(count=6, weight=(2.0, 12.0), area_min=(1.0, 1.0), area_max=(6.0, 9.0)),
        destination=Destination((9.5, 5.0), 2.8),
    )
    app.check(config, WORLD)
    boxes = place_objects(config, np.random.default_rng(7))
    again = place_objects(config, np.random.default_rng(7))
    assert boxes == again
    assert [box.obj for box in boxes] == list(range(1, 8))
    assert len({box.drop for box in boxes}) == 7
    assert all(1.0 <= box.x <= 6.0 and 2.0 <= box.weight <= 12.0 for box in boxes[1:])


def test_every_message_has_a_tag_of_its_own_named_by_its_module() -> None:
    tags = [cls.__struct_config__.tag for cls in MESSAGES]
    assert len(set(tags)) == len(tags)
    assert all(wire_name(cls) == f"apps.box_moving.messages.{cls.__name__}" for cls in MESSAGES)
