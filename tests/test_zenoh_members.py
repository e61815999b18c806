"""Who may place, move and remove a robot of a Zenoh swarm: the rules, without a network.

``Members`` is fed token keys as Zenoh hands them over (appeared, went); the tests
read where each robot is placed, the news of robots joining, moving and leaving,
and the refusals. Real sessions and a real stranger are in ``test_zenoh_stranger``.
"""

from __future__ import annotations

import hmac
from typing import Any

import pytest

from cas_async import SwarmKey
from cas_async._wire._presence import PresenceSeal
from cas_async.transport.zenoh._members import MAX_CLAIMS, Members

KEY = SwarmKey(bytes(range(32)))
OTHER_KEY = SwarmKey(b"\xa5" * 32)
HERE, THERE, FAKE, LATER = "aa" * 16, "bb" * 16, "cc" * 16, "dd" * 16


def unsigned(robot: int, zid: str) -> str:
    return f"ns/alive/{robot}/{zid}"


def signed(robot: int, zid: str, stamp: int, key: SwarmKey = KEY) -> str:
    """A signed token's key, its proof computed independently of ``PresenceSeal``."""
    claim = f"ns/alive/{robot}/{zid}/{stamp}"
    derived = hmac.new(key.secret, b"cas_async presence v1", "sha256").digest()
    return f"{claim}/{hmac.new(derived, claim.encode(), 'sha256').hexdigest()[:32]}"


class Swarm:
    """Members of session ``HERE``, and everything they said."""

    def __init__(self, key: SwarmKey | None = None) -> None:
        self.news: list[tuple[int, str | None, str | None]] = []
        self.refused: list[tuple[str, int | None]] = []
        self.details: list[str] = []
        self.members = Members("ns", self._changed, self._refused)
        self.members.zid = HERE
        if key is not None:
            self.members.require(PresenceSeal(key))

    def _changed(self, robot: int, before: str | None, after: str | None) -> None:
        self.news.append((robot, before, after))

    def _refused(self, reason: str, detail: str, robot: int | None) -> None:
        self.refused.append((reason, robot))
        self.details.append(detail)

    def appear(self, *keys: str) -> None:
        for key in keys:
            self.members.appeared(key)

    def go(self, *keys: str) -> None:
        for key in keys:
            self.members.went(key)

    @property
    def placed(self) -> dict[int, str]:
        return self.members.placed


# -- without a key -----------------------------------------------------------------------------


def test_a_second_token_neither_moves_nor_removes_a_placed_robot() -> None:
    swarm = Swarm()
    swarm.appear(unsigned(3, THERE), unsigned(3, FAKE))
    assert swarm.placed == {3: THERE}
    assert swarm.refused == [("token_conflict", 3)]
    assert f"robot 3: the token of session {FAKE} is refused: it lives in session {THERE}" in (
        swarm.details
    )
    swarm.go(unsigned(3, FAKE))
    assert swarm.placed == {3: THERE}
    assert swarm.news == [(3, None, THERE)]


def test_the_placed_token_going_removes_the_robot_or_hands_it_to_the_next_claim() -> None:
    # A robot restarted elsewhere before its old token went: it moves there when it goes.
    swarm = Swarm()
    swarm.appear(unsigned(3, THERE), unsigned(3, LATER))
    swarm.go(unsigned(3, THERE))
    assert swarm.placed == {3: LATER}
    swarm.go(unsigned(3, LATER))
    assert swarm.placed == {}
    assert swarm.news == [(3, None, THERE), (3, THERE, LATER), (3, LATER, None)]


def test_a_robot_of_this_process_stays_here_whatever_others_claim() -> None:
    swarm = Swarm()
    key = swarm.members.attach(3)
    assert key == unsigned(3, HERE)
    swarm.appear(unsigned(3, FAKE))
    assert swarm.placed == {3: HERE}
    assert swarm.refused == [("token_conflict", 3)]
    assert "it lives in session this process" in swarm.details[0]
    swarm.appear(unsigned(3, HERE))  # the echo of its own token: known already
    swarm.go(unsigned(3, HERE), unsigned(3, FAKE))
    assert swarm.placed == {3: HERE}
    swarm.members.detach(3)
    assert swarm.placed == {}
    assert swarm.news == [(3, None, HERE), (3, HERE, None)]


def test_claims_kept_aside_are_bounded() -> None:
    swarm = Swarm()
    swarm.appear(unsigned(3, THERE))
    fakes = [f"{n:032x}" for n in range(1, MAX_CLAIMS + 5)]
    swarm.appear(*(unsigned(3, zid) for zid in fakes))
    assert swarm.refused == [("token_conflict", 3)] * len(fakes)
    assert sum("forgotten" in detail for detail in swarm.details) == 5
    swarm.go(unsigned(3, THERE), *(unsigned(3, zid) for zid in fakes[: MAX_CLAIMS - 1]))
    assert swarm.placed == {}  # the ones forgotten were never kept


@pytest.mark.parametrize(
    "key",
    [
        "ns/alive/3",
        "ns/alive/three/" + THERE,
        "ns/alive/3/ZZ",
        "ns/alive/3/" + THERE + "/extra",
        "ns/alive/3/" + THERE + "/12/" + "ab" * 15,  # a proof too short
        "ns/alive/3/" + "a" * 33,
        "other/alive/3/" + THERE,
    ],
    ids=["no zid", "no int", "no zid digits", "one word more", "short proof", "long", "other ns"],
)
def test_a_malformed_token_is_counted_and_places_nobody(key: str) -> None:
    swarm = Swarm()
    swarm.appear(key)
    swarm.go(key)
    assert swarm.placed == {}
    assert swarm.refused == [("token_malformed", None)]


# -- with a key --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("key", "reason"),
    [
        (unsigned(3, THERE), "token_unsigned"),
        (signed(3, THERE, 100, OTHER_KEY), "token_forged"),
        (signed(3, THERE, 100)[:-1] + "0", "token_forged"),
        (signed(3, THERE, 100).replace(THERE, FAKE), "token_forged"),  # another session
        (signed(3, THERE, 100).replace("/3/", "/4/"), "token_forged"),  # another robot
        (signed(3, THERE, 100).replace("/100/", "/101/"), "token_forged"),  # another stamp
    ],
    ids=["unsigned", "other key", "altered proof", "moved", "renamed", "restamped"],
)
def test_with_a_key_only_a_proven_token_places_a_robot(key: str, reason: str) -> None:
    swarm = Swarm(KEY)
    swarm.appear(key)
    assert swarm.placed == {}
    assert swarm.refused[0][0] == reason
    swarm.appear(signed(3, THERE, 100))
    assert swarm.placed == {3: THERE}


def test_with_a_key_the_newest_proven_token_places_the_robot() -> None:
    # A robot restarted elsewhere moves at once, even while its old process's token
    # lives (frozen, until Zenoh's lease ends); an older token moves nothing.
    swarm = Swarm(KEY)
    swarm.appear(signed(3, THERE, 100), signed(3, LATER, 200), signed(3, FAKE, 150))
    assert swarm.placed == {3: LATER}
    assert swarm.refused == [("token_conflict", 3)]
    swarm.go(signed(3, THERE, 100))
    assert swarm.placed == {3: LATER}
    swarm.go(signed(3, LATER, 200))  # the older ones kept aside do not come back
    assert swarm.placed == {}
    assert swarm.news == [(3, None, THERE), (3, THERE, LATER), (3, LATER, None)]


def test_with_a_key_a_copy_of_a_token_that_went_is_refused() -> None:
    swarm = Swarm(KEY)
    swarm.appear(signed(3, THERE, 100))
    swarm.go(signed(3, THERE, 100))
    swarm.appear(signed(3, THERE, 100), signed(3, FAKE, 90))
    assert swarm.placed == {}
    assert swarm.refused == [("token_replayed", 3)] * 2
    swarm.appear(signed(3, LATER, 101))  # the robot comes back
    assert swarm.placed == {3: LATER}


def test_with_a_key_this_process_signs_its_tokens_and_keeps_its_robots() -> None:
    swarm = Swarm(KEY)
    key = swarm.members.attach(3)
    robot, zid, stamp = key.split("/")[2:5]
    assert (robot, zid) == ("3", HERE)
    assert key == signed(3, HERE, int(stamp))
    assert swarm.members.attach(4) != signed(4, HERE, int(stamp))  # stamps only grow
    swarm.appear(signed(3, THERE, int(stamp) + 10**9))  # newer, but 3 lives here
    assert swarm.placed == {3: HERE, 4: HERE}
    assert swarm.refused == [("token_conflict", 3)]
    swarm.members.detach(3)  # then the newer claim elsewhere is where it is
    assert swarm.placed == {3: THERE, 4: HERE}


def test_a_key_given_late_judges_the_tokens_heard_again() -> None:
    swarm = Swarm()
    swarm.appear(unsigned(3, THERE), signed(4, THERE, 100))
    assert swarm.placed == {3: THERE, 4: THERE}
    swarm.members.require(PresenceSeal(KEY))
    assert swarm.placed == {4: THERE}
    assert swarm.refused == [("token_unsigned", 3)]
    assert swarm.news[-1] == (3, THERE, None)


def test_the_seal_shows_no_key() -> None:
    seal: Any = PresenceSeal(KEY)
    assert KEY.secret.hex() not in repr(seal)
    assert seal.verifies("ns/alive/3/" + THERE + "/1", "zz" * 16) is False
