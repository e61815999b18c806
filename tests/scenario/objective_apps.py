"""A toy application for the Objective tests: robots that do chores, an objective that counts them.

Each robot does ``chores.per_robot`` chores, one every ``chores.period`` simulated
seconds; robot ``k``'s are at ``j * period + k / 10`` (``j`` from 1), so robots 1
to 3 with a period of 1 do theirs at 1.1, 1.2, 1.3, 2.1, ... The chores are
recorded on a :class:`Board`, the app's own world, which the objective follows
(it never asks a layer). A scenario names the app ``tests.scenario.objective_apps``.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Hashable
from dataclasses import dataclass
from pathlib import Path

from cas_async import Layer, Pose, Robot, RobotId
from cas_async.scenario import Mission, Objective, RunResult, SimulationSetup, Tally, Watch, setting
from cas_async.scenario.output import Trace

__all__ = ["Board", "ChoreCount", "Chores", "ChoresApp", "ChoresConfig", "Doer", "app"]


@dataclass(frozen=True)
class Chores:
    """The ``[chores]`` table."""

    robots: int = setting(3, ge=1, doc="robots")
    per_robot: int = setting(3, ge=0, doc="chores each robot does")
    period: float = setting(1.0, gt=0, doc="simulated seconds between a robot's chores")
    target: int = setting(5, ge=0, doc="chores for the mission to be complete")
    audit_fails_at: float = setting(-1.0, doc="check() raises from this instant on (< 0: never)")
    figure: bool = setting(False, doc="figures() writes chores.txt")
    measure_fails: str = setting(
        "", doc='measure() sets a dict as an extra ("extra") or raises ("raises"); "": neither'
    )


@dataclass(frozen=True)
class ChoresConfig:
    chores: Chores = setting(default_factory=Chores)


class Board:
    """Every chore done: by whom and when; tells its subscribers of each."""

    def __init__(self) -> None:
        self.done: list[tuple[RobotId, float]] = []
        self._subscribers: list[Callable[[RobotId, float], None]] = []

    def subscribe(self, callback: Callable[[RobotId, float], None]) -> None:
        self._subscribers.append(callback)

    def record(self, robot_id: RobotId, t: float) -> None:
        self.done.append((robot_id, t))
        for callback in self._subscribers:
            callback(robot_id, t)


class Doer(Layer):
    """Does ``count`` chores, one every ``period`` seconds from ``period + offset``."""

    def __init__(self, board: Board, count: int, period: float, offset: float) -> None:
        self.board = board
        self.left = count
        self.period = period
        self.next_at = period + offset

    async def inner_process(self) -> None:
        if self.left and self.wake_due("chore") is None:
            self.wake_at(self.next_at, "chore")

    async def on_timer(self, key: Hashable) -> None:
        self.board.record(self.robot_id, self.next_at)  # the planned instant: exact
        self.left -= 1
        self.next_at += self.period


class ChoreCount(Objective):
    """``target`` chores done; every chore reported as an exchange, and past the target too.

    Attributes:
        watch: what it reports to, once attached.
        completions: every instant it called ``watch.completed`` at.
        measured_at: the ``end`` given to :meth:`measure`.
    """

    noun = "chore"
    verb = "done"
    detail = "busy robots"
    kind = "chores"

    def __init__(
        self, board: Board, target: int, audit_fails_at: float, figure: bool, measure_fails: str
    ) -> None:
        self._board = board
        self._target = target
        self._audit_fails_at = audit_fails_at
        self._figure = figure
        self._measure_fails = measure_fails
        self.watch: Watch | None = None
        self.completions: list[float] = []
        self.measured_at: float | None = None

    @property
    def target(self) -> int:
        return self._target

    def attach(self, watch: Watch) -> None:
        self.watch = watch
        self._board.subscribe(self._on_chore)

    def _on_chore(self, robot_id: RobotId, t: float) -> None:
        if self.watch is None:
            return
        done = len(self._board.done)
        self.watch.exchanged(t, done)
        self.watch.changed(t)
        if done >= self._target:  # again at every chore past the target: the runner ignores it
            self.completions.append(t)
            self.watch.completed(t)

    def _busy(self) -> set[RobotId]:
        return {robot_id for robot_id, _ in self._board.done}

    def progress(self) -> Tally:
        return Tally(len(self._board.done), len(self._busy()))

    def check(self) -> None:
        if self.watch is None or self._audit_fails_at < 0:
            return
        now = self.watch.clock.now()
        if now >= self._audit_fails_at:
            raise RuntimeError(f"audit failed at t={now:g}: the board disagrees with itself")

    def carrying(self) -> Collection[RobotId]:
        return self._busy()

    def measure(self, result: RunResult, end: float) -> None:
        self.measured_at = end
        counted = self._board.done[: self._target]
        times = [t for _, t in counted]
        result.delivered = len(counted)
        result.delivery_times = times
        result.samples["chore_time"] = times
        result.samples["gap"] = [b - a for a, b in zip([0.0, *times], times, strict=False)]
        result.extra["busy_robots"] = len(self._busy())
        if self._measure_fails == "extra":  # not one figure: refused here
            result.extra["by_robot"] = {robot_id: 1 for robot_id in self._busy()}  # type: ignore[assignment]
        if self._measure_fails == "raises":
            raise ZeroDivisionError("no chores per robot to divide")
        result.extra["label"] = "toy"

    def figures(self, trace: Trace, out_dir: Path) -> list[Path]:
        if not self._figure:
            return []
        path = out_dir / "chores.txt"
        lines = [f"{robot_id} {t:g}" for robot_id, t in self._board.done]
        path.write_text("\n".join([f"samples {len(trace.times)}", *lines]) + "\n")
        return [path]


class ChoresApp:
    name = "Chores"
    item_name = "chore"
    config_type = ChoresConfig

    def robots(self, config: ChoresConfig) -> dict[str, int]:
        return {"chores.robots": config.chores.robots}

    def check(self, config: ChoresConfig, world: tuple[float, float]) -> None:
        pass

    def build(self, setup: SimulationSetup[ChoresConfig]) -> Mission:
        chores, board = setup.config.chores, Board()
        robots = []
        for robot_id in range(1, chores.robots + 1):
            setup.environment.add_robot(robot_id, Pose(float(robot_id), 1.0, 0.0))
            doer = Doer(board, chores.per_robot, chores.period, robot_id / 10)
            robots.append(Robot(robot_id, [doer], transport=setup.transport, clock=setup.clock))
        objective = ChoreCount(
            board, chores.target, chores.audit_fails_at, chores.figure, chores.measure_fails
        )
        return Mission(robots, objective=objective)


app = ChoresApp()
