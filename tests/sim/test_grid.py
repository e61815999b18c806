"""The range-query grid: CellGrid on its own, and Environment.within with it against brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cas_async import ConstantSpeed, Decelerating, PiecewiseSpeed, Pose, Positions
from cas_async.sim import Environment, Motion, Phase
from cas_async.sim._grid import CellGrid
from cas_async.sim._segments import SegmentTable

GRID_FROM = 64  # the Environment uses its grid from this many robots on


def brute_within(env: Environment, robot_id: int, radius: float, t: float) -> Positions:
    """What within() answered before the grid: every robot evaluated, nearest first."""
    everyone = env.positions_at(t)
    index = env.robot_ids.index(robot_id)
    offsets = everyone.xy - everyone.xy[index]
    squared = np.einsum("ij,ij->i", offsets, offsets)
    inside = squared <= radius * radius
    inside[index] = False
    found = np.flatnonzero(inside)
    order = found[np.lexsort((everyone.ids[found], squared[found]))]
    return Positions(everyone.ids[order], everyone.xy[order])


def assert_same(found: Positions, expected: Positions) -> None:
    assert found.ids.tolist() == expected.ids.tolist()
    assert found.xy.tolist() == expected.xy.tolist()  # to the last bit
    assert not found.ids.flags.writeable
    assert not found.xy.flags.writeable


# -- CellGrid --------------------------------------------------------------------------


def test_a_row_is_found_from_every_cell_its_box_overlaps() -> None:
    grid = CellGrid(1.0)
    grid.place(7, 0.5, 0.5, 3.5, 0.5)  # a segment along x over cells 0..3
    assert len(grid) == 1
    assert 7 in grid
    for x in (0.5, 1.5, 2.5, 3.5):
        assert grid.rows_near(x, 0.5, x, 0.5) == {7}
    assert grid.rows_near(5.5, 0.5, 6.5, 0.5) == set()


def test_moving_a_row_unfiles_it_from_its_old_cells() -> None:
    grid = CellGrid(1.0)
    grid.place(1, 0.5, 0.5, 0.5, 0.5)
    grid.place(1, 9.5, 9.5, 9.5, 9.5)
    assert grid.rows_near(0.0, 0.0, 1.0, 1.0) == set()
    assert grid.rows_near(9.0, 9.0, 9.9, 9.9) == {1}
    grid.remove(1)
    grid.remove(1)  # twice: nothing happens
    assert len(grid) == 0
    assert grid.rows_near(-100.0, -100.0, 100.0, 100.0) == set()


def test_a_box_on_a_cell_boundary_is_also_filed_next_to_it() -> None:
    # (2.0, 2.0) computed on a segment may come out a hair below 2.0: the slack
    # files it under the cells on both sides of the boundary.
    grid = CellGrid(1.0)
    grid.place(3, 2.0, 2.0, 2.0, 2.0)
    assert grid.rows_near(1.5, 1.5, 1.9999999999, 1.9999999999) == {3}


def test_a_query_wider_than_the_occupied_cells_looks_only_at_those() -> None:
    grid = CellGrid(1.0)
    grid.place(1, 0.5, 0.5, 0.5, 0.5)
    grid.place(2, 50.5, 50.5, 50.5, 50.5)
    assert grid.cells_over(-1e6, -1e6, 1e6, 1e6) > 10**12
    assert grid.rows_near(-1e6, -1e6, 1e6, 1e6) == {1, 2}
    assert grid.rows_near(40.0, 40.0, 1e6, 1e6) == {2}


@pytest.mark.parametrize("cell", [0.0, -1.0, math.inf, math.nan])
def test_a_cell_must_be_a_finite_positive_number(cell: float) -> None:
    with pytest.raises(ValueError, match="cell must be a finite number > 0"):
        CellGrid(cell)


def test_a_box_must_have_finite_corners() -> None:
    with pytest.raises(ValueError, match="row 4's box must have finite corners"):
        CellGrid(1.0).place(4, 0.0, 0.0, math.inf, 0.0)


@settings(max_examples=60, deadline=None)
@given(
    boxes=st.lists(st.tuples(*[st.floats(-50, 50, allow_nan=False)] * 4), min_size=1, max_size=40),
    query=st.tuples(*[st.floats(-60, 60, allow_nan=False)] * 2),
    reach=st.floats(0, 30),
    cell=st.sampled_from([0.3, 1.0, 5.0, 25.0]),
)
def test_rows_near_covers_every_box_that_meets_the_query(
    boxes: list[tuple[float, float, float, float]],
    query: tuple[float, float],
    reach: float,
    cell: float,
) -> None:
    grid = CellGrid(cell)
    for row, box in enumerate(boxes):
        grid.place(row, *box)
    qx0, qy0, qx1, qy1 = query[0] - reach, query[1] - reach, query[0] + reach, query[1] + reach
    found = grid.rows_near(qx0, qy0, qx1, qy1)
    for row, (x0, y0, x1, y1) in enumerate(boxes):
        meets = (
            min(x0, x1) <= qx1 and max(x0, x1) >= qx0 and min(y0, y1) <= qy1 and max(y0, y1) >= qy0
        )
        if meets:
            assert row in found


# -- SegmentTable.positions_of --------------------------------------------------------------


def test_positions_of_some_rows_are_those_rows_of_all_positions() -> None:
    table = SegmentTable()
    rng = np.random.default_rng(5)
    for k in range(100):
        here = Pose(*rng.uniform(0, 20, 2), 0.0)
        profile = ConstantSpeed(3.0) if k % 2 else Decelerating(3.0, 0.5, 0.6)
        table.append(
            float(k % 7),
            Motion.straight_to(here, *rng.uniform(0, 20, 2), turn_rate=math.pi, profile=profile),
        )
    rows = np.array([98, 3, 3, 50, 0], dtype=np.intp)
    for t in (0.0, 2.5, 6.1, 40.0):
        assert table.positions_of(t, rows).tolist() == table.positions(t)[rows].tolist()
    assert table.box(3)[:2] == tuple(table.positions(-math.inf)[3].tolist())


def test_the_position_of_one_row_is_that_row_of_all_positions_to_the_last_bit() -> None:
    """position() computes one row in plain floats; it must give numpy's very numbers."""
    table = SegmentTable()
    rng = np.random.default_rng(11)
    three_phases = PiecewiseSpeed(
        (Phase(0.7, 0.0, 2.0), Phase(1.1, 1.4, -0.5), Phase(math.inf, 0.85, 0.0))
    )
    profiles = [ConstantSpeed(3.0), Decelerating(3.0, 0.5, 0.6), three_phases]
    boundaries: list[float] = []
    for k in range(120):
        here = Pose(*rng.uniform(-20, 20, 2), rng.uniform(-3, 3))
        if k % 10 == 0:
            motion = Motion.standing(here)
        elif k % 10 == 1:
            motion = Motion.turn_to(here, rng.uniform(-3, 3), turn_rate=1.0)
        else:
            target = rng.uniform(-20, 20, 2)
            profile = profiles[k % 3]
            motion = Motion.straight_to(here, *target, turn_rate=math.pi, profile=profile)
        start = float(rng.uniform(0, 8))
        table.append(start, motion)
        # the instants its translation, each phase and the motion begin or end
        moving = start + motion.rotation_time
        starts = motion.profile.starts() if motion.profile is not None else ()
        boundaries += [start + motion.duration, *(moving + t0 for t0, _, _ in starts)]
    instants = [-math.inf, 0.0, *rng.uniform(0, 60, 300).tolist(), *boundaries]
    for t in instants:
        everyone = table.positions(t)
        for row in range(len(table)):
            assert table.position(row, t) == tuple(everyone[row].tolist()), (row, t)


# -- Environment.within with the grid ---------------------------------------------------------


def crowd(n: int, seed: int, *, cell_size: float | None = None) -> Environment:
    env = Environment(cell_size=cell_size)
    rng = np.random.default_rng(seed)
    for robot_id in range(1, n + 1):
        x, y = rng.uniform(0, 40, 2)
        env.add_robot(robot_id, Pose(x, y, 0.0), mobile=robot_id % 9 != 0)
    return env


def wander(env: Environment, rng: np.random.Generator, t: float, moves: int) -> None:
    """Starts ``moves`` random straight moves at instant ``t``."""
    ids = [r for r in env.robot_ids if env.is_mobile(r)]
    for robot_id in rng.choice(ids, size=moves, replace=False).tolist():
        here = env.pose_at(robot_id, t)
        profile = ConstantSpeed(3.0) if robot_id % 2 else Decelerating(3.0, 0.5, 0.6)
        target = rng.uniform(-5, 45, 2)
        env.start_motion(
            robot_id, Motion.straight_to(here, *target, turn_rate=math.pi, profile=profile), t
        )


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    n=st.integers(GRID_FROM, 160),
    radius=st.sampled_from([0.0, 0.5, 3.0, 5.0, 12.0, 1e6, math.inf]),
    cell_size=st.sampled_from([None, 0.7, 5.0, 100.0]),
)
def test_within_with_the_grid_answers_as_brute_force(
    seed: int, n: int, radius: float, cell_size: float | None
) -> None:
    env = crowd(n, seed, cell_size=cell_size)
    rng = np.random.default_rng(seed)
    t = 0.0
    for _ in range(4):
        wander(env, rng, t, moves=n // 3)
        for dt in (-1.0, 0.0, 0.4, 1.7, 9.0):  # before, during and after the moves
            asker = int(rng.integers(1, n + 1))
            assert_same(env.within(asker, radius, t + dt), brute_within(env, asker, radius, t + dt))
        t += 2.0


def test_the_grid_takes_the_first_finite_radius_as_its_cell() -> None:
    env = crowd(GRID_FROM, 1)
    env.within(1, math.inf, 0.0)  # everyone: no grid needed
    env.within(1, 0.0, 0.0)  # a zero radius says nothing about the cells
    assert env._grid is None
    env.within(1, 4.0, 0.0)
    assert env._grid is not None
    assert env._grid.cell == 4.0


def test_a_small_swarm_does_not_build_a_grid() -> None:
    env = crowd(GRID_FROM - 1, 1)
    assert_same(env.within(2, 10.0, 0.0), brute_within(env, 2, 10.0, 0.0))
    assert env._grid is None


def test_robots_added_and_removed_after_the_grid_is_built_are_found_or_gone() -> None:
    env = crowd(GRID_FROM, 2, cell_size=2.0)
    env.within(1, 3.0, 0.0)  # builds the grid
    env.add_robot(500, env.pose_at(1, 0.0))  # right on robot 1
    assert 500 in env.within(1, 0.5, 0.0).ids.tolist()
    env.remove_robot(500)
    env.remove_robot(3)  # rows after it are renumbered: the grid is rebuilt
    for asker in (1, 2, 4, GRID_FROM):
        for radius in (3.0, 9.0):
            assert_same(env.within(asker, radius, 0.0), brute_within(env, asker, radius, 0.0))


@pytest.mark.parametrize("cell_size", [0.0, -2.0, math.inf, math.nan])
def test_the_cell_size_must_be_a_finite_positive_number(cell_size: float) -> None:
    with pytest.raises(ValueError, match="cell_size must be a finite number > 0"):
        Environment(cell_size=cell_size)
