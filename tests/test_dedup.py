"""Duplicate suppression: the per-sender window, kept replies, and what a robot refuses."""

from __future__ import annotations

import asyncio
import math

import pytest

import cas_async
from cas_async import (
    Faults,
    FaultyTransport,
    MemoryTransport,
    Message,
    MsgType,
    Robot,
    Swarm,
    VirtualClock,
)
from cas_async._core._dedup import (
    DUPLICATE,
    FRESH,
    FUTURE,
    STALE,
    WINDOW,
    ReplyCache,
    SenderWindows,
)
from cas_async.transport import Codec
from tests.stacks import STACK_MESSAGES, Answer, Note, Query, Recorder
from tests.taps import Tap

# -- SenderWindows ---------------------------------------------------------------------


def test_first_message_of_a_sender_is_fresh_and_its_repeat_a_duplicate() -> None:
    windows = SenderWindows()
    assert windows.check(7, 100, 0.0) == FRESH
    assert windows.check(7, 100, 0.0) == DUPLICATE
    assert windows.check(7, 101, 0.0) == FRESH
    assert windows.check(7, 100, 0.0) == DUPLICATE
    assert windows.check(7, 101, 0.0) == DUPLICATE


def test_senders_are_told_apart() -> None:
    windows = SenderWindows()
    assert windows.check(1, 5, 0.0) == FRESH
    assert windows.check(2, 5, 0.0) == FRESH  # the same id from another robot is news
    assert windows.check(1, 5, 0.0) == DUPLICATE
    assert len(windows) == 2


def test_reordering_inside_the_window_is_fresh_once() -> None:
    windows = SenderWindows()
    assert windows.check(1, 10, 0.0) == FRESH
    assert windows.check(1, 8, 0.0) == FRESH  # overtaken by 10, still new
    assert windows.check(1, 9, 0.0) == FRESH
    assert windows.check(1, 8, 0.0) == DUPLICATE
    assert windows.check(1, 9, 0.0) == DUPLICATE
    assert windows.check(1, 7, 0.0) == FRESH


@pytest.mark.parametrize(
    ("behind", "expected"),
    [
        pytest.param(WINDOW - 1, FRESH, id="oldest-id-the-window-holds"),
        pytest.param(WINDOW, STALE, id="just-below-the-window"),
        pytest.param(10 * WINDOW, STALE, id="far-below"),
    ],
)
def test_ids_below_the_window_are_stale(behind: int, expected: int) -> None:
    windows = SenderWindows()
    highest = 5 * WINDOW
    windows.check(1, highest, 0.0)
    assert windows.check(1, highest - behind, 0.0) == expected


def test_an_id_seen_at_the_far_edge_of_the_window_is_still_a_duplicate() -> None:
    windows = SenderWindows()
    windows.check(1, 1, 0.0)
    windows.check(1, WINDOW, 0.0)  # 1 is now WINDOW - 1 below the highest
    assert windows.check(1, 1, 0.0) == DUPLICATE
    windows.check(1, WINDOW + 1, 0.0)  # 1 has slid out
    assert windows.check(1, 1, 0.0) == STALE


def test_a_window_over_many_ids_keeps_a_bounded_mask() -> None:
    windows = SenderWindows()
    for msg_id in range(1, 5 * WINDOW):
        assert windows.check(1, msg_id, 0.0) == FRESH
    window = windows._windows[1]
    assert window.mask.bit_length() <= WINDOW
    assert windows.check(1, 5 * WINDOW - 1 - (WINDOW - 1), 0.0) == DUPLICATE


@pytest.mark.parametrize("jump", [WINDOW, WINDOW + 1, 10**18], ids=["window", "window+1", "1e18"])
def test_a_jump_of_a_window_or_more_starts_afresh_without_a_huge_mask(jump: int) -> None:
    windows = SenderWindows()
    for msg_id in (1, 2, 3):
        windows.check(1, msg_id, 0.0)
    assert windows.check(1, 3 + jump, 0.0) == FRESH
    window = windows._windows[1]
    assert (window.highest, window.mask) == (3 + jump, 1)  # no shift by ``jump`` happened
    assert windows.check(1, 3 + jump, 0.0) == DUPLICATE
    assert windows.check(1, 3 + jump - 1, 0.0) == FRESH  # nothing below is marked seen


def test_a_jump_just_short_of_the_window_keeps_what_was_seen() -> None:
    windows = SenderWindows()
    windows.check(1, 3, 0.0)
    assert windows.check(1, 3 + WINDOW - 1, 0.0) == FRESH
    assert windows.check(1, 3, 0.0) == DUPLICATE


def test_beyond_max_senders_the_sender_tracked_longest_is_forgotten() -> None:
    windows = SenderWindows(max_senders=2)
    windows.check(1, 10, 1.0)
    windows.check(2, 10, 2.0)
    windows.check(1, 11, 3.0)  # heard again, but still the one tracked longest
    windows.check(3, 10, 4.0)
    assert len(windows) == 2
    assert windows.heard(1) is None
    assert (windows.heard(2), windows.heard(3)) == (2.0, 4.0)
    assert windows.check(1, 10, 5.0) == FRESH  # forgotten: taken as new
    assert windows.heard(2) is None  # and 2 made room for it
    assert len(windows) == 2


def test_many_claimed_senders_cannot_grow_memory() -> None:
    windows = SenderWindows(max_senders=100)
    for sender in range(10_000):
        windows.check(sender, 1, 0.0)
    assert len(windows) == 100


def test_heard_is_the_time_of_the_latest_message_whatever_its_verdict() -> None:
    windows = SenderWindows()
    assert windows.heard(1) is None
    windows.check(1, 5 * WINDOW, 5.0)
    assert windows.heard(1) == 5.0
    assert windows.check(1, 5 * WINDOW, 7.0) == DUPLICATE
    assert windows.heard(1) == 7.0
    assert windows.check(1, 1, 9.0) == STALE
    assert windows.heard(1) == 9.0
    assert windows.heard(2) is None


def test_a_forgotten_id_is_fresh_again_and_nothing_else_changes() -> None:
    windows = SenderWindows()
    for msg_id in (1, 2, 3):
        windows.check(1, msg_id, 0.0)
    windows.check(2, 2, 0.0)
    windows.forget(1, 2)  # e.g. refused by a full inbox: not delivered after all
    assert windows.check(1, 2, 1.0) == FRESH
    assert windows.check(1, 2, 1.0) == DUPLICATE
    assert (windows.check(1, 1, 1.0), windows.check(1, 3, 1.0)) == (DUPLICATE, DUPLICATE)
    assert windows.check(2, 2, 1.0) == DUPLICATE  # another sender's window is untouched


def test_forgetting_the_highest_or_a_sender_s_first_id_makes_it_fresh_again() -> None:
    windows = SenderWindows()
    windows.check(1, 10, 0.0)  # first message of this sender
    windows.forget(1, 10)
    assert windows.check(1, 10, 0.0) == FRESH
    windows.check(1, 10 + 5 * WINDOW, 0.0)  # a jump: the window starts afresh
    windows.forget(1, 10 + 5 * WINDOW)
    assert windows.check(1, 10 + 5 * WINDOW, 0.0) == FRESH


@pytest.mark.parametrize(
    ("sender", "msg_id"),
    [
        pytest.param(9, 5, id="unknown-sender"),
        pytest.param(1, 5 * WINDOW + 1, id="above-the-highest"),
        pytest.param(1, 5 * WINDOW - WINDOW, id="below-the-window"),
    ],
)
def test_forgetting_what_the_window_does_not_hold_changes_nothing(sender: int, msg_id: int) -> None:
    windows = SenderWindows()
    windows.check(1, 5 * WINDOW, 0.0)
    windows.forget(sender, msg_id)
    assert windows.check(1, 5 * WINDOW, 0.0) == DUPLICATE
    assert windows._windows[1].mask.bit_length() <= WINDOW
    assert len(windows) == 1


# -- ReplyCache ------------------------------------------------------------------------


def test_reply_cache_keeps_replies_by_asker_and_request() -> None:
    cache = ReplyCache()
    cache.keep(1, 10, b"to 1", 0.0)
    cache.keep(2, 10, b"to 2", 0.0)
    assert (cache.get(1, 10), cache.get(2, 10)) == (b"to 1", b"to 2")
    assert cache.get(1, 11) is None
    assert cache.get(3, 10) is None


def test_reply_cache_keeps_a_reply_for_its_time_however_many_others_come() -> None:
    cache = ReplyCache(keep_for=5.0)
    cache.keep(1, 1, b"first", 0.0)
    for request_id in range(2, 1002):  # many quick questions from the same asker
        cache.keep(1, request_id, b"quick", 0.004 * request_id)
    assert cache.get(1, 1) == b"first"  # 4 s old: still there
    cache.keep(2, 1, b"later", 5.5)
    assert cache.get(1, 1) == b"first"  # kept at least keep_for, at most about twice
    cache.keep(2, 2, b"much later", 10.6)
    assert cache.get(1, 1) is None  # more than twice keep_for: gone
    assert cache.get(2, 1) == b"later"
    assert len(cache) == 2


def test_reply_cache_stays_within_its_budget_dropping_the_oldest() -> None:
    per_reply = 100 + ReplyCache.OVERHEAD
    cache = ReplyCache(keep_for=1e9, budget=10 * per_reply)
    for request_id in range(1000):
        cache.keep(request_id % 7, request_id, b"x" * 100, float(request_id))
        assert cache.size <= 10 * per_reply
    assert 5 <= len(cache) <= 10
    assert [cache.get(r % 7, r) is not None for r in (0, 989, 995, 999)] == [
        False,
        False,
        True,
        True,
    ]


def test_reply_cache_counts_a_reply_kept_again_once() -> None:
    cache = ReplyCache(keep_for=60.0)
    cache.keep(1, 1, b"abc", 0.0)
    cache.keep(1, 1, b"abcdef", 1.0)
    assert (len(cache), cache.get(1, 1)) == (1, b"abcdef")
    assert cache.size == 6 + ReplyCache.OVERHEAD


def test_reply_cache_with_no_memory_keeps_only_the_last_replies() -> None:
    cache = ReplyCache(keep_for=0.0)
    cache.keep(1, 1, b"a", 0.0)
    cache.keep(1, 2, b"b", 0.0)
    cache.keep(1, 3, b"c", 0.0)
    assert [cache.get(1, r) for r in (1, 2, 3)] == [None, b"b", b"c"]


# -- the horizon of message ids -----------------------------------------------------------


def test_an_id_beyond_the_horizon_is_refused_and_changes_nothing() -> None:
    windows = SenderWindows()
    horizon = lambda: 1_000_000  # noqa: E731
    assert windows.check(1, 2**63, 5.0, horizon) == FUTURE  # first sight: nothing kept
    assert windows.heard(1) is None
    assert windows.check(1, 500, 6.0, horizon) == FRESH
    assert windows.check(1, 2**63, 7.0, horizon) == FUTURE  # a forged jump moves nothing
    assert windows.heard(1) == 6.0
    assert windows.check(1, 501, 8.0, horizon) == FRESH  # real news still fresh
    assert windows.check(1, 900_000, 9.0, horizon) == FRESH  # a restart within the horizon


# -- end to end ------------------------------------------------------------------------


class Counting(Recorder):
    """Records every external message handled, with its simulated time."""

    def __init__(self) -> None:
        super().__init__()
        self.times: list[float] = []

    async def handle_msg(self, msg: Message) -> None:
        self.times.append(self.clock.now())
        await super().handle_msg(msg)


def robot(robot_id: int, layer: Recorder, transport: object, clock: VirtualClock) -> Robot:
    return Robot(
        robot_id,
        [layer],
        transport=transport,  # type: ignore[arg-type]
        clock=clock,
        messages=STACK_MESSAGES,
    )


def test_network_duplicates_are_handled_once_and_counted() -> None:
    async def main() -> tuple[list[str], dict[str, int], dict[str, int]]:
        clock, memory = VirtualClock(), MemoryTransport()
        faulty = FaultyTransport(memory, Faults(duplicate=1.0), seed=1, clock=clock)
        sender, receiver = Recorder(), Counting()
        robots = [robot(1, sender, faulty, clock), robot(2, receiver, memory, clock)]
        async with Swarm(robots):
            for k in range(50):
                sender.send(2, Note(str(k), []))
            await clock.sleep(1.0)
        return [m.text for m in receiver.external], robots[1].dropped, faulty.stats  # type: ignore[attr-defined]

    texts, dropped, stats = cas_async.run(main(), virtual=True)
    assert texts == [str(k) for k in range(50)]
    assert stats["duplicated"] == 50
    assert dropped == {"duplicate": 50}


def test_duplicated_reordered_and_delayed_messages_are_each_handled_once() -> None:
    async def main() -> tuple[list[str], dict[str, int], dict[str, int]]:
        clock, memory = VirtualClock(), MemoryTransport()
        faults = Faults(duplicate=0.5, reorder=0.3, delay=(0.0, 0.2))
        faulty = FaultyTransport(memory, faults, seed=7, clock=clock)
        sender, receiver = Recorder(), Counting()
        robots = [robot(1, sender, faulty, clock), robot(2, receiver, memory, clock)]
        async with Swarm(robots):
            for k in range(300):
                sender.send(2, Note(str(k), []))
                await clock.sleep(0.01)
            await clock.sleep(5.0)
        return [m.text for m in receiver.external], robots[1].dropped, faulty.stats  # type: ignore[attr-defined]

    texts, dropped, stats = cas_async.run(main(), virtual=True)
    assert sorted(texts, key=int) == [str(k) for k in range(300)]  # each exactly once
    assert texts != sorted(texts, key=int)  # the wire did reorder them
    assert stats["duplicated"] > 0
    assert dropped == {"duplicate": stats["duplicated"]}


class AnswerOnce(Recorder):
    """Answers queries; its transport loses exactly its first send (the first reply)."""

    def __init__(self, lossy: FaultyTransport) -> None:
        super().__init__()
        self.lossy = lossy

    async def handle_msg(self, msg: Message) -> None:
        await super().handle_msg(msg)  # replies: lost on the wire
        self.lossy.faults = Faults()  # every later send gets through


def test_a_request_whose_reply_was_lost_gets_the_kept_reply_without_being_handled_again() -> None:
    async def main() -> tuple[float, int, int, dict[str, int], dict[str, int], dict[str, int]]:
        clock, memory = VirtualClock(), MemoryTransport()
        lossy = FaultyTransport(memory, Faults(loss=1.0), clock=clock)
        asker, answerer = Recorder(), AnswerOnce(lossy)
        robots = [robot(1, asker, memory, clock), robot(2, answerer, lossy, clock)]
        async with Swarm(robots):
            reply = await asker.request(2, Query(21), timeout=2.0, retries=1)
            at = clock.now()
            await clock.sleep(10.0)
        assert isinstance(reply, Answer)
        return (
            at,
            reply.value,
            len(answerer.external),
            robots[1].counters(),
            robots[1].dropped,
            robots[0].dropped,
        )

    at, value, handled, counters, dropped, asker_dropped = cas_async.run(main(), virtual=True)
    assert value == 42
    assert at == 2.0  # the re-sent request at the timeout got the kept reply at once
    assert handled == 1
    assert counters["replies_resent"] == 1
    assert dropped == {"duplicate": 1}
    assert asker_dropped == {}


def test_a_lost_reply_is_still_re_sent_after_other_quick_requests_from_the_same_asker() -> None:
    # More quick questions during one timeout than the answerer once kept per asker (16).
    quick_count = 40

    async def main() -> tuple[int | Exception, list[int], int]:
        clock, memory = VirtualClock(), MemoryTransport()
        lossy = FaultyTransport(memory, Faults(loss=1.0), clock=clock)
        asker, answerer = Recorder(), AnswerOnce(lossy)
        robots = [robot(1, asker, memory, clock), robot(2, answerer, lossy, clock)]
        async with Swarm(robots):
            slow = asyncio.ensure_future(asker.request(2, Query(100), timeout=5.0, retries=1))
            await clock.sleep(1.0)  # its reply was lost; it waits for its retry at t=5
            quick = [await asker.request(2, Query(k), timeout=5.0) for k in range(quick_count)]
            try:
                first: int | Exception = (await slow).value  # type: ignore[attr-defined]
            except cas_async.RequestTimeout as error:
                first = error
        return first, [reply.value for reply in quick], len(answerer.external)  # type: ignore[attr-defined]

    first, quick, handled = cas_async.run(main(), virtual=True)
    assert quick == [2 * k for k in range(quick_count)]
    assert handled == quick_count + 1
    assert first == 200


def test_a_reply_to_a_robot_that_left_is_dropped_as_undeliverable() -> None:
    class Slow(Recorder):
        async def handle_msg(self, msg: Message) -> None:
            self.external.append(msg)
            await self.clock.sleep(5.0)  # the asker gives up and leaves meanwhile
            self.reply(msg, Answer(1, 0))

    async def main() -> tuple[dict[str, int], int]:
        clock, memory = VirtualClock(), MemoryTransport()
        slow = Slow()
        answerer = robot(2, slow, memory, clock)
        async with answerer:
            asker = Recorder()
            async with robot(1, asker, memory, clock):
                asking = asyncio.ensure_future(asker.request(2, Query(1), timeout=60.0))
                await clock.sleep(1.0)
            with pytest.raises(cas_async.RobotStateError):
                await asking
            await clock.sleep(10.0)
            return answerer.dropped, len(slow.external)

    dropped, handled = cas_async.run(main(), virtual=True)
    assert handled == 1
    assert dropped == {"reply_undeliverable": 1}


def test_a_request_refused_by_a_full_inbox_is_handled_when_sent_again() -> None:
    class Slow(Recorder):
        async def handle_msg(self, msg: Message) -> None:
            await self.clock.sleep(1.0)
            await super().handle_msg(msg)

    async def main() -> tuple[list[object], dict[str, int]]:
        clock, memory = VirtualClock(), MemoryTransport()
        asker, slow = Recorder(), Slow()
        answerer = Robot(
            2, [slow], transport=memory, clock=clock, messages=STACK_MESSAGES, queue_limit=2
        )
        async with Swarm([robot(1, asker, memory, clock), answerer]):
            replies = await asyncio.gather(
                *(asker.request(2, Query(k), timeout=4.0, retries=3) for k in range(5)),
                return_exceptions=True,
            )
        return [getattr(r, "value", r) for r in replies], answerer.dropped

    values, dropped = cas_async.run(main(), virtual=True)
    assert dropped["queue_full"] >= 3  # five at once, two fit: the retries are the remedy
    assert values == [0, 2, 4, 6, 8]


# -- who may claim to have sent a datagram -----------------------------------------------


def encoded(msg: Message, *, claims: int, msg_id: int) -> bytes:
    """``msg`` as robot ``claims`` of a one-layer stack would send it to layer 0."""
    msg.msg_id, msg.robot_id, msg.src_layer, msg.dst_layer = msg_id, claims, 0, 0
    return Codec.for_stack(1, STACK_MESSAGES).encode(msg)


@pytest.mark.parametrize(
    ("claims", "sender", "outcome"),
    [
        pytest.param(2, 2, "delivered", id="honest"),
        pytest.param(2, None, "unknown_source", id="a-known-robot-claimed-from-nobody-s-address"),
        pytest.param(3, 2, "spoofed_sender", id="claims-another-known-robot"),
        pytest.param(9, 2, "spoofed_sender", id="claims-an-unknown-robot-with-a-known-sender"),
        pytest.param(9, None, "unknown_source", id="claims-a-robot-nobody-can-reach"),
        pytest.param(1, None, "unknown_source", id="claims-the-receiver-from-nobody-s-address"),
        pytest.param(1, 2, "from_own_id", id="claims-the-receiver-sent-by-another"),
    ],
)
def test_the_claimed_sender_must_be_the_one_the_transport_names(
    claims: int, sender: int | None, outcome: str
) -> None:
    async def main() -> tuple[int, dict[str, int]]:
        clock, tap = VirtualClock(), Tap()
        receiver = Counting()
        robots = [robot(1, receiver, tap, clock)] + [
            robot(i, Recorder(), tap, clock) for i in (2, 3)
        ]
        async with Swarm(robots):
            tap.deliver(1, encoded(Note("hello", []), claims=claims, msg_id=5), sender)
            await clock.sleep(1.0)
        return len(receiver.external), robots[0].dropped

    handled, dropped = cas_async.run(main(), virtual=True)
    if outcome == "delivered":
        assert (handled, dropped) == (1, {})
    else:
        assert (handled, dropped) == (0, {outcome: 1})


def test_forged_requests_are_not_reflected_and_do_not_silence_the_robot_they_claim() -> None:
    """Issue 16: 200,000 forged requests claiming swarm robots made 197,853 replies to
    them, and the robots' real messages were then refused as stale."""

    async def main() -> tuple[dict[int, int], dict[str, int], list[int]]:
        clock, tap = VirtualClock(), Tap()
        answerer, claimed = Recorder(), Recorder()
        robots = [robot(1, answerer, tap, clock), robot(2, claimed, tap, clock)]
        robots.append(robot(3, Recorder(), tap, clock))
        async with Swarm(robots):
            before = {r: len(tap.received[r]) for r in (2, 3)}
            for k in range(500):  # claiming robot 2, ids no honest robot has used yet
                request = Query(k)
                request.msg_type = MsgType.NEGOTIATION
                forged = encoded(request, claims=2, msg_id=2**62 + k)
                tap.deliver(1, forged, 3)  # from robot 3's address
                tap.deliver(1, forged, None)  # from an address that is no robot's
            await clock.sleep(1.0)
            replies = {r: len(tap.received[r]) - before[r] for r in (2, 3)}
            answer = await claimed.request(1, Query(21), timeout=1.0)  # robot 2, for real
            assert isinstance(answer, Answer)
        return replies, robots[0].dropped, [m.value for m in answerer.external]

    replies, dropped, handled = cas_async.run(main(), virtual=True)
    assert replies == {2: 0, 3: 0}  # nobody was sent a reply to a forgery
    assert dropped == {"spoofed_sender": 500, "unknown_source": 500}
    assert handled == [21]  # and robot 2's real request was not stale


def test_a_refused_datagram_does_not_mark_its_id_as_seen() -> None:
    async def main() -> tuple[int, dict[str, int], float | None]:
        clock, tap = VirtualClock(), Tap()
        receiver = Counting()
        robots = [robot(1, receiver, tap, clock), robot(2, Recorder(), tap, clock)]
        async with Swarm(robots):
            await clock.sleep(3.0)
            forged = encoded(Note("forged", []), claims=2, msg_id=5)
            tap.deliver(1, forged, 3)  # spoofed: must not burn id 5 of robot 2
            heard_after_forgery = robots[0].last_heard(2)
            tap.deliver(1, encoded(Note("honest", []), claims=2, msg_id=5), 2)
            await clock.sleep(1.0)
        return len(receiver.external), robots[0].dropped, heard_after_forgery

    handled, dropped, heard = cas_async.run(main(), virtual=True)
    assert (handled, dropped) == (1, {"spoofed_sender": 1})
    assert heard is None  # a forgery does not count as hearing from robot 2


# -- a robot that comes back under the same id -------------------------------------------


def test_a_robot_restarted_under_the_same_id_is_heard_by_a_peer_that_kept_running() -> None:
    async def main() -> tuple[list[str], dict[str, int], list[float]]:
        clock, memory = VirtualClock(), MemoryTransport()
        listener = Counting()
        async with robot(1, listener, memory, clock) as peer:
            for life in range(3):
                talker = Recorder()
                async with robot(2, talker, memory, clock):
                    for k in range(5):
                        talker.send(1, Note(f"{life}.{k}", []))
                    await clock.sleep(1.0)
                await clock.sleep(4.0)  # robot 2 is gone for a while, then comes back
            return [m.text for m in listener.external], peer.dropped, listener.times  # type: ignore[attr-defined]

    texts, dropped, times = cas_async.run(main(), virtual=True)
    assert texts == [f"{life}.{k}" for life in range(3) for k in range(5)]
    assert dropped == {}
    assert times == [0.0] * 5 + [5.0] * 5 + [10.0] * 5


@pytest.mark.parametrize("gap", [0.0, 2e-6], ids=["same-instant", "two-microseconds-later"])
def test_a_robot_restarted_soon_after_a_burst_is_still_heard(gap: float) -> None:
    async def main() -> tuple[list[str], dict[str, int]]:
        clock, memory = VirtualClock(), MemoryTransport()
        listener = Counting()
        async with robot(1, listener, memory, clock) as peer:
            await clock.sleep(1.0)
            for life in range(2):
                talker = Recorder()
                async with robot(2, talker, memory, clock):
                    for k in range(5):  # a burst: no simulated time passes
                        talker.send(1, Note(f"{life}.{k}", []))
                    for _ in range(5):
                        await asyncio.sleep(0)
                await clock.sleep(gap)
            await clock.sleep(1.0)
            return [m.text for m in listener.external], peer.dropped  # type: ignore[attr-defined]

    texts, dropped = cas_async.run(main(), virtual=True)
    assert (texts, dropped) == ([f"{life}.{k}" for life in range(2) for k in range(5)], {})


def test_last_heard_counts_duplicates_and_is_none_for_strangers() -> None:
    async def main() -> tuple[float | None, float | None, float, float]:
        clock, memory = VirtualClock(), MemoryTransport()
        faulty = FaultyTransport(memory, Faults(duplicate=1.0, delay=(3.0, 3.0)), clock=clock)
        sender, receiver = Recorder(), Counting()
        robots = [robot(1, sender, faulty, clock), robot(2, receiver, memory, clock)]
        async with Swarm(robots):
            await clock.sleep(2.0)
            sender.send(2, Note("x", []))
            await clock.sleep(10.0)
            return (
                robots[1].last_heard(1),
                robots[1].last_heard(3),
                receiver.silent_for(1),
                receiver.silent_for(3),
            )

    heard, stranger, silent, silent_stranger = cas_async.run(main(), virtual=True)
    assert heard == 5.0
    assert stranger is None
    assert silent == 7.0
    assert silent_stranger == math.inf


def test_a_negotiation_duplicated_before_it_is_answered_is_handled_once() -> None:
    async def main() -> tuple[int, int, dict[str, int], dict[str, int]]:
        clock, memory = VirtualClock(), MemoryTransport()
        faulty = FaultyTransport(memory, Faults(duplicate=1.0), clock=clock)
        asker, answerer = Recorder(), Counting()
        robots = [robot(1, asker, faulty, clock), robot(2, answerer, faulty, clock)]
        async with Swarm(robots):
            reply = await asker.request(2, Query(5), timeout=1.0)
            assert isinstance(reply, Answer)
            assert reply.value == 10
            assert reply.msg_type == MsgType.ACCEPT
            await clock.sleep(1.0)
        return (
            len(answerer.external),
            robots[1].counters()["replies_resent"],
            robots[1].dropped,
            robots[0].dropped,
        )

    handled, resent, answerer_dropped, asker_dropped = cas_async.run(main(), virtual=True)
    assert handled == 1
    # Both copies of the request arrive before it is answered: nothing kept to re-send yet.
    assert (resent, answerer_dropped) == (0, {"duplicate": 1})
    assert asker_dropped == {"duplicate": 1}  # the reply's own network copy
