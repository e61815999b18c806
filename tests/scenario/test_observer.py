"""A run's observer: records applied to a mirror in one canonical order, sampled between them."""

from __future__ import annotations

import asyncio
import itertools
import math
import random

import msgspec
import pytest

from cas_async import ConstantSpeed, Pose, SimulationError, VirtualClock
from cas_async.scenario._processes._observer import (
    ItemRecord,
    MotionRecord,
    Observation,
    Observer,
    Recorder,
    mirror_of,
)
from cas_async.sim import Environment, ItemEventKind, Motion


def standing_world(count: int = 3) -> Environment:
    env = Environment()
    for robot_id in range(1, count + 1):
        env.add_robot(robot_id, Pose(float(robot_id), 0.0, 0.0))
    return env


def straight(start: Pose, x: float, y: float) -> Motion:
    return Motion.straight_to(start, x, y, turn_rate=math.inf, profile=ConstantSpeed(1.0))


def motion_record(t: float, robot: int, n: int, x: float) -> MotionRecord:
    """Robot ``robot``'s ``n``-th motion: from where it starts to ``(x, 0)``."""
    return MotionRecord(t, robot, n, straight(Pose(float(robot), 0, 0), x, 0).to_numbers())


def created(t: float, robot: int, n: int, item: int) -> ItemRecord:
    return ItemRecord(t, robot, n, "created", item, robot, None)


class Samples:
    """What each sample saw of the mirror: the instant, robot 1's x, the items made."""

    def __init__(self, mirror: Environment) -> None:
        self.mirror = mirror
        self.taken: list[tuple[float, float, int]] = []

    async def __call__(self, t: float) -> None:
        self.taken.append((t, self.mirror.pose_at(1, t).x, self.mirror.items.created))


def observer(interval: float = 1.0, done: bool | None = None) -> tuple[Observer, Samples]:
    mirror = mirror_of(standing_world())
    samples = Samples(mirror)
    finished = (lambda: mirror.items.created >= 2) if done is None else (lambda: done)
    return Observer(mirror, interval, samples, finished), samples


# -- the mirror ----------------------------------------------------------------------------


def test_the_mirror_has_every_robot_where_it_stands_and_no_latency() -> None:
    clock = VirtualClock()
    env = Environment(latency=0.5, clock=clock)
    env.add_robot(4, Pose(1, 2, 0.5))
    env.add_robot(2, Pose(-3, 0, 0), mobile=False)
    mirror = mirror_of(env)
    assert mirror.robot_ids == (4, 2)
    assert (mirror.pose_at(4, 0.0), mirror.pose_at(2, 9.0)) == (Pose(1, 2, 0.5), Pose(-3, 0, 0))
    assert (mirror.is_mobile(4), mirror.is_mobile(2), mirror.latency) == (True, False, 0.0)


@pytest.mark.parametrize("halted", [False, True], ids=["moving", "moved-and-stopped"])
def test_a_mirror_of_a_robot_that_moved_already_is_refused_naming_it(halted: bool) -> None:
    env = standing_world()
    env.start_motion(3, straight(Pose(3, 0, 0), 5, 0), 0.0)
    if halted:
        env.halt(3, 0.5)
    with pytest.raises(SimulationError, match="robot 3 moves before the run starts"):
        mirror_of(env)


# -- records -------------------------------------------------------------------------------


def test_records_travel_as_msgpack_and_give_back_their_events() -> None:
    observation = Observation(
        [motion_record(0.5, 1, 1, 4.0)], [ItemRecord(1.0, 2, 1, "transferred", 7, 1, 2)]
    )
    data = msgspec.msgpack.encode(observation)
    assert msgspec.msgpack.decode(data, type=Observation) == observation
    event = observation.items[0].event()
    assert (event.t, event.kind, event.item, event.robot, event.receiver, event.actor) == (
        1.0,
        ItemEventKind.TRANSFERRED,
        7,
        1,
        2,
        2,
    )
    assert observation
    assert not Observation()


@pytest.mark.cas_virtual
async def test_a_recorder_records_its_robots_motions_and_every_item_event_counted_per_robot() -> (
    None
):
    env = standing_world()
    recorder = Recorder(env, [1, 2])
    item = env.create_item(1, 0.0)
    env.start_motion(1, straight(Pose(1, 0, 0), 4, 0), 0.0)
    env.start_motion(3, straight(Pose(3, 0, 0), 9, 0), 0.0)  # not one of its robots
    env.start_motion(2, straight(Pose(2, 0, 0), 0, 0), 0.5)
    env.halt(1, 1.0)
    env.hand_over(item, 1, 2, 1.0, reach=math.inf)
    window = recorder.take()
    assert [(m.t, m.robot, m.n) for m in window.motions] == [(0.0, 1, 1), (0.5, 2, 1), (1.0, 1, 2)]
    assert Motion.from_numbers(window.motions[0].numbers).end == Pose(4, 0, 0)
    assert [(i.t, i.actor, i.n, i.kind) for i in window.items] == [
        (0.0, 1, 1, "created"),
        (1.0, 2, 1, "transferred"),  # in the receiver's hands: its own count
    ]
    assert not recorder.take()  # taken: the next window starts empty
    env.halt(2, 2.0)
    assert [(m.robot, m.n) for m in recorder.take().motions] == [(2, 2)]


# -- applying and sampling -----------------------------------------------------------------


def applied_order(observations: list[Observation]) -> tuple[tuple[str, int, float], ...]:
    """In which order a mirror sees the records of ``observations``."""
    mirror = mirror_of(standing_world())
    order: list[tuple[str, int, float]] = []
    mirror.watch_motions(lambda robot, _motion, start: order.append(("motion", robot, start)))
    mirror.items.subscribe(lambda event: order.append(("item", event.item, event.t)))
    Observer(mirror, 1.0, Samples(mirror), lambda: False).apply(observations, until=3.0)
    return tuple(order)


def test_records_are_applied_in_one_order_whatever_order_they_come_in() -> None:
    records: list[MotionRecord | ItemRecord] = [
        motion_record(1.0, 2, 1, 7.0),
        motion_record(1.0, 1, 1, 5.0),
        created(1.0, 1, 1, 11),  # an item of the same instant: after the motions
        created(1.0, 1, 2, 12),
        created(0.5, 3, 1, 31),
        MotionRecord(2.0, 1, 2, straight(Pose(2, 0, 0), 9, 0).to_numbers()),  # from where it is
    ]
    outcomes = set()
    rng = random.Random(28)
    for _ in range(30):
        rng.shuffle(records)
        cut = rng.randrange(len(records) + 1)  # spread over two processes' observations
        parts = [records[:cut], records[cut:]]
        observations = [
            Observation(
                [r for r in part if isinstance(r, MotionRecord)],
                [r for r in part if isinstance(r, ItemRecord)],
            )
            for part in parts
        ]
        outcomes.add(applied_order(observations))
    assert outcomes == {
        (
            ("item", 31, 0.5),
            ("motion", 1, 1.0),
            ("motion", 2, 1.0),
            ("item", 11, 1.0),
            ("item", 12, 1.0),
            ("motion", 1, 2.0),
        )
    }


async def test_samples_come_at_every_tick_before_a_windows_end_and_between_the_records() -> None:
    watcher, samples = observer(interval=1.0, done=False)
    first = Observation([motion_record(0.5, 1, 1, 5.0)], [created(2.0, 1, 1, 11)])
    await watcher.window(3.0, [first])
    # 0, 1, 2 but not 3 (the window's end is the next one's); a sample sees the mirror
    # once every record of its instant is applied (the item made at 2.0).
    assert samples.taken == [(0.0, 1.0, 0), (1.0, 1.5, 0), (2.0, 2.5, 1)]
    assert (watcher.until, watcher.next_sample) == (3.0, 3.0)
    await watcher.window(4.5, [Observation()])
    assert [t for t, _, _ in samples.taken] == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert samples.taken[3] == (3.0, 3.5, 1)
    await watcher.window(5.0, [])
    assert [t for t, _, _ in samples.taken][-1] == 4.0  # 5.0 is not before 5.0


async def test_sample_until_takes_each_sample_once_and_the_last_one_only_if_inclusive() -> None:
    watcher, samples = observer(interval=0.5, done=False)
    await watcher.sample_until(1.0, inclusive=False)
    assert [t for t, _, _ in samples.taken] == [0.0, 0.5]
    await watcher.sample_until(1.0, inclusive=True)
    await watcher.sample_until(1.0, inclusive=True)
    assert [t for t, _, _ in samples.taken] == [0.0, 0.5, 1.0]
    assert (watcher.until, watcher.next_sample) == (1.0, 1.5)
    await watcher.sample_until(0.2, inclusive=True)  # the past: nothing
    assert len(samples.taken) == 3


async def test_nothing_is_applied_nor_sampled_once_the_run_is_done() -> None:
    watcher, samples = observer(interval=1.0)  # done once two items are made
    window = Observation(
        [motion_record(2.5, 1, 1, 5.0)],
        [created(0.5, 2, 1, 21), created(1.5, 3, 1, 31), created(2.0, 2, 2, 22)],
    )
    await watcher.window(4.0, [window])
    mirror = watcher.mirror
    assert mirror.items.created == 2  # the one made at 2.0 came after the end
    assert mirror.motion_of(1)[1] == -math.inf  # nor the motion at 2.5
    assert [t for t, _, _ in samples.taken] == [0.0, 1.0]  # none after the end either
    await watcher.window(6.0, [Observation([], [created(4.5, 1, 1, 11)])])
    watcher.apply([Observation([], [created(6.5, 1, 2, 12)])], until=7.0)
    assert (mirror.items.created, len(samples.taken)) == (2, 2)
    assert watcher.until < 4.0


def test_apply_applies_without_sampling_and_says_up_to_when_the_mirror_is_complete() -> None:
    watcher, samples = observer(interval=1.0, done=False)
    watcher.apply([Observation([motion_record(0.5, 1, 1, 5.0)], [created(2.0, 1, 1, 11)])])
    assert (samples.taken, watcher.until) == ([], 0.0)
    watcher.apply([Observation()], until=3.0)
    watcher.apply([Observation()], until=2.0)  # never back
    assert watcher.until == 3.0
    assert watcher.mirror.pose_at(1, 3.0) == Pose(3.5, 0.0, 0.0)
    assert watcher.mirror.items.holder(11) == 1


@pytest.mark.cas_virtual
async def test_a_recorded_world_and_its_mirror_agree_at_every_sample() -> None:
    clock = VirtualClock()
    clock.start()
    env = Environment(latency=0.25, clock=clock)
    for robot_id in range(1, 5):
        env.add_robot(robot_id, Pose(float(robot_id), 0.0, 0.0))
    recorder, mirror = Recorder(env, env.robot_ids), mirror_of(env)
    truth: list[dict[int, tuple[float, float]]] = []
    seen: list[dict[int, tuple[float, float]]] = []

    async def sample(t: float) -> None:
        truth.append(env.positions_at(t).as_dict())
        seen.append(mirror.positions_at(t).as_dict())

    watcher = Observer(mirror, 0.5, sample, lambda: False)
    rng = random.Random(3)
    for k in itertools.count(1):
        t = k * 0.25
        if t > 4.0:
            break
        await clock.sleep_until(t)
        for robot_id in rng.sample(range(1, 5), 2):
            here = env.pose_at(robot_id, t)
            env.start_motion(robot_id, straight(here, rng.uniform(0, 5), rng.uniform(0, 5)), t)
        await asyncio.sleep(0)
        await watcher.window(t + 0.25, [recorder.take()])
    assert len(truth) == 9
    assert seen == truth


def test_a_recorder_keeping_its_motions_hands_the_observer_the_motions_themselves() -> None:
    env = standing_world()
    recorder = Recorder(env, env.robot_ids, keep=True)
    mirror = mirror_of(env)
    watcher = Observer(mirror, 1.0, Samples(mirror), lambda: False, recorder.kept)
    first, second = straight(Pose(1, 0, 0), 4, 0), straight(Pose(2, 0, 0), 0, 0)
    env.start_motion(1, first, 0.0)
    env.start_motion(2, second, 0.5)
    window = recorder.take()
    assert recorder.kept == {(1, 1): first, (2, 1): second}
    watcher.apply([window], until=1.0)
    # Applied as they are, not rebuilt from their numbers (the same, to the bit):
    assert mirror.motion_of(1)[0] is first
    assert mirror.motion_of(2)[0] is second
    assert recorder.kept == {}  # taken out once applied


def test_an_observer_of_other_processes_rebuilds_each_motion_from_its_numbers() -> None:
    env = standing_world()
    recorder = Recorder(env, env.robot_ids)  # a worker's: its motions travel as numbers
    mirror = mirror_of(env)
    motion = straight(Pose(1, 0, 0), 4, 0)
    env.start_motion(1, motion, 0.0)
    Observer(mirror, 1.0, Samples(mirror), lambda: False).apply([recorder.take()], until=1.0)
    assert recorder.kept is None
    rebuilt = mirror.motion_of(1)[0]
    assert rebuilt is not motion
    assert rebuilt.to_numbers() == motion.to_numbers()  # its profile as phases
