"""What a box-moving mission is for: ``target`` objects moved, the Floor audited all along.

:class:`MoveObjects` is the app's :class:`~cas_async.scenario.Objective`. It follows
the :class:`~apps.box_moving.floor.Floor`'s events: the mission is complete at
the instant the ``target``-th object is moved (put down in the zone by its
last lifter), and only the objects moved up to then are measured. Progress is
the objects moved, beside the joint carries begun. Every sample of the run
audits the Floor's whole invariant; the robots lifting an object are the ones
carrying.
"""

from __future__ import annotations

from collections.abc import Collection
from pathlib import Path

from cas_async.scenario import Objective, RunResult, Tally, Watch
from cas_async.scenario.output import Trace

from .floor import Floor
from .records import FloorEvent, FloorEventKind

__all__ = ["MoveObjects"]


class MoveObjects(Objective):
    """Move ``target`` objects to the destination (see the module docs).

    Args:
        floor: the run's objects.
        target: objects to move.
        world: the area's width and height (for the figure).

    Raises:
        ValueError: ``target`` is negative or more than the objects on the floor.
    """

    noun = "object"
    verb = "moved"
    detail = "joint carries"
    kind = "boxes"
    distributable = False

    def __init__(self, floor: Floor, target: int, world: tuple[float, float]) -> None:
        if not 0 <= target <= len(floor.boxes):
            raise ValueError(
                f"MoveObjects: target must be within 0..{len(floor.boxes)}, got {target}"
            )
        self.floor = floor
        self._target = target
        self._world = world
        self._watch: Watch | None = None
        self._joint = 0  # joint carries begun
        self._measured: int | None = None  # objects moved when the target was reached

    @property
    def target(self) -> int:
        """Objects to move."""
        return self._target

    def attach(self, watch: Watch) -> None:
        """Follows the Floor's events."""
        self._watch = watch
        self.floor.subscribe(self._on_event)
        if self._target == 0:
            watch.completed(watch.clock.now())

    def _on_event(self, event: FloorEvent) -> None:
        watch = self._watch
        if watch is None or self._measured is not None:  # what comes after is not the run's
            return
        if event.kind is FloorEventKind.CARRIED and len(event.robots) == 2:
            self._joint += 1
            watch.changed(event.t)
        elif event.kind is FloorEventKind.MOVED:
            if self.floor.moved == self._target:
                self._measured = self.floor.moved
                watch.completed(event.t)
            watch.changed(event.t)

    def progress(self) -> Tally:
        """Objects moved, and joint carries begun."""
        moved = self.floor.moved if self._measured is None else self._measured
        return Tally(moved, self._joint)

    def check(self) -> None:
        """The Floor's full audit, at the run's instant."""
        if self._watch is not None:
            self.floor.audit(self._watch.clock.now())

    def carrying(self) -> Collection[int]:
        """The robots lifting an object."""
        return self.floor.lifters()

    def measure(self, result: RunResult, end: float) -> None:
        """Objects moved, when, how long each took from selection, how far it went."""
        del end
        done = self.floor.deliveries()
        if self._measured is not None:
            done = done[: self._measured]
        result.delivered = len(done)
        result.delivery_times = [delivery.t for delivery in done]
        result.samples["time_per_object"] = [delivery.t - delivery.selected for delivery in done]
        result.samples["carry_distance"] = [delivery.distance for delivery in done]
        joint = sum(delivery.joint for delivery in done)
        result.extra["joint_carries"] = joint
        result.extra["solo_carries"] = len(done) - joint
        result.extra["objects_left"] = len(self.floor.boxes) - len(done)

    def figures(self, trace: Trace, out_dir: Path) -> list[Path]:
        """``objects.png``: the robots' paths, and each object's from where it lay to its drop."""
        from .figures import draw_objects  # matplotlib is imported only here

        return [draw_objects(self.floor, trace, self._world, out_dir / "objects.png")]
