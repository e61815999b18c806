"""Which worker runs which robot: strips of neighbours, round robin, or the application's own."""

from __future__ import annotations

import itertools
import random
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import pytest

from cas_async import Pose
from cas_async.scenario._processes._partition import partition
from cas_async.sim import Environment

SCENARIOS = Path(__file__).resolve().parents[2] / "apps" / "fire_brigade" / "scenarios"


def placed(positions: dict[int, tuple[float, float]]) -> Environment:
    env = Environment()
    for robot_id, (x, y) in positions.items():
        env.add_robot(robot_id, Pose(x, y, 0.0))
    return env


def test_regions_are_strips_along_the_longer_side_neighbours_together() -> None:
    # A wide world: robots 1..10 at x = 10 - k, so their ids run against x.
    positions = {k: (10.0 - k, float(k % 3)) for k in range(1, 11)}
    env = placed(positions)
    shares = partition(env, list(positions), 3, "region")
    assert shares == [[10, 9, 8, 7], [6, 5, 4], [3, 2, 1]]
    for left, right in itertools.pairwise(shares):
        assert max(positions[r][0] for r in left) < min(positions[r][0] for r in right)


def test_a_tall_world_is_cut_along_y_and_ties_go_by_the_other_axis_then_id() -> None:
    positions = {1: (0.0, 9.0), 2: (1.0, 0.0), 3: (0.0, 0.0), 4: (0.5, 5.0), 5: (0.0, 5.0)}
    env = placed(positions)
    assert partition(env, list(positions), 2, "region") == [[3, 2, 5], [4, 1]]
    same = placed({7: (1.0, 1.0), 3: (1.0, 1.0), 5: (1.0, 1.0)})
    assert partition(same, [7, 3, 5], 3, "region") == [[3], [5], [7]]


def test_regions_read_the_robots_where_they_stand_at_time_zero() -> None:
    env = placed({1: (0.0, 0.0), 2: (1.0, 0.0), 3: (2.0, 0.0), 4: (3.0, 0.0)})
    assert partition(env, [4, 3, 2, 1], 2, "region") == [[1, 2], [3, 4]]


def test_round_robin_deals_the_robots_out_in_turn() -> None:
    env = placed({k: (float(k), 0.0) for k in range(1, 8)})
    robots = [7, 1, 6, 2, 5, 3, 4]
    assert partition(env, robots, 3, "round_robin") == [[7, 2, 4], [1, 5], [6, 3]]


@pytest.mark.parametrize("kind", ["region", "round_robin"])
def test_every_robot_is_in_exactly_one_share_and_the_shares_are_even(kind: str) -> None:
    rng = random.Random(28)
    for _ in range(40):
        count = rng.randrange(1, 60)
        positions = {
            rng.randrange(1000) * 100 + k: (rng.uniform(-50, 50), rng.uniform(-5, 5))
            for k in range(count)
        }
        robots = list(positions)
        workers = rng.randrange(1, count + 1)
        shares = partition(placed(positions), robots, workers, kind)  # type: ignore[arg-type]
        assert len(shares) == workers
        assert sorted(r for share in shares for r in share) == sorted(robots)
        assert max(map(len, shares)) - min(map(len, shares)) <= 1


@pytest.mark.parametrize(("robots", "workers"), [(3, 4), (3, 0), (0, 1)])
def test_more_workers_than_robots_or_none_is_refused_naming_both(robots: int, workers: int) -> None:
    env = placed({k: (float(k), 0.0) for k in range(1, robots + 1)})
    with pytest.raises(ValueError, match=f"^{robots} robots cannot be shared by {workers} workers"):
        partition(env, list(range(1, robots + 1)), workers, "region")


class OwnPartition:
    """An application that puts robots by parity (an odd one per worker), or as told."""

    def __init__(self, groups: Sequence[Sequence[int]] | None = None) -> None:
        self.groups = groups
        self.asked: list[tuple[int, ...]] = []

    def partition(
        self, environment: Environment, robots: Sequence[int], workers: int
    ) -> Sequence[Sequence[int]]:
        self.asked.append((len(environment), len(robots), workers))
        if self.groups is not None:
            return self.groups
        return [[r for r in robots if r % 2 == 0], [r for r in robots if r % 2 == 1]]


def test_an_applications_own_partition_wins_over_the_kind() -> None:
    env = placed({k: (float(k), 0.0) for k in range(1, 7)})
    app = OwnPartition()
    for kind in ("region", "round_robin"):
        assert partition(env, list(range(1, 7)), 2, kind, app) == [[2, 4, 6], [1, 3, 5]]  # type: ignore[arg-type]
    assert app.asked == [(6, 6, 2), (6, 6, 2)]
    assert partition(env, list(range(1, 7)), 2, "region", object()) == [[1, 2, 3], [4, 5, 6]]


@pytest.mark.parametrize(
    ("groups", "message"),
    [
        ([[1, 2, 3, 4]], "must be 2 groups, none empty"),
        ([[1, 2, 3, 4], []], "must be 2 groups, none empty"),
        ([[1, 2], [3]], "must hold every robot exactly once"),
        ([[1, 2], [2, 3, 4]], "must hold every robot exactly once"),
        ([[1, 2], [3, 9]], "must hold every robot exactly once"),
    ],
    ids=["too-few", "empty", "missing", "twice", "stranger"],
)
def test_an_applications_partition_that_is_no_partition_is_refused(
    groups: list[list[int]], message: str
) -> None:
    env = placed({k: (float(k), 0.0) for k in range(1, 5)})
    with pytest.raises(ValueError, match=f"the app's partition {message}"):
        partition(env, [1, 2, 3, 4], 2, "region", OwnPartition(groups))


def test_a_run_with_more_processes_than_robots_is_a_usage_error_naming_both(
    tmp_path: Path,
) -> None:
    pytest.importorskip("zenoh", reason="--processes needs the zenoh extra: it says so first")
    scenario = SCENARIOS / "thesis_5_8_1.toml"  # 20 robots
    command = [sys.executable, "-m", "cas_async", "run", str(scenario), "--virtual"]
    done = subprocess.run(
        [*command, "--no-plots", "--processes", "21", "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 2, done.stderr
    assert "20 robots" in done.stderr
    assert "21 worker" in done.stderr
