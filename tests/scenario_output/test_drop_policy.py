"""FailOnDrops: which drops fail a run, and what the run's result says then."""

from __future__ import annotations

import pytest

from cas_async.scenario import FailOnDrops, RunResult, RunStatus
from cas_async.scenario.output import results_dict, summary_table


def result(status: RunStatus = RunStatus.COMPLETED, **drops: int) -> RunResult:
    run = RunResult(scenario="s.toml", app="App", item_name="item", seed=1, status=status)
    run.protocol_errors = {reason.replace("__", "."): n for reason, n in drops.items()}
    return run


@pytest.mark.parametrize(
    ("text", "reasons"),
    [
        pytest.param("", frozenset(), id="any"),
        pytest.param("queue_full", {"queue_full"}, id="one"),
        pytest.param("decode, queue_full,", {"decode", "queue_full"}, id="several"),
        pytest.param("decode.wrong_type", {"decode.wrong_type"}, id="dotted"),
    ],
)
def test_parse(text: str, reasons: set[str]) -> None:
    assert FailOnDrops.parse(text).reasons == reasons


@pytest.mark.parametrize("text", ["Queue-Full", "decode..x", "a b", ".decode"])
def test_parse_refuses_what_is_no_reason(text: str) -> None:
    with pytest.raises(ValueError, match="expected drop reasons such as"):
        FailOnDrops.parse(text)


@pytest.mark.parametrize(
    ("reasons", "reason", "fails"),
    [
        (frozenset(), "duplicate", True),
        ({"decode"}, "decode.wrong_type", True),
        ({"decode"}, "decoder", False),
        ({"decode.wrong_type"}, "decode.truncated", False),
        ({"queue_full"}, "queue_full", True),
        ({"queue_full"}, "duplicate", False),
    ],
)
def test_a_reason_names_itself_and_its_family(
    reasons: frozenset[str], reason: str, fails: bool
) -> None:
    assert FailOnDrops(frozenset(reasons)).fails_for(reason) is fails


def test_drops_for_a_named_reason_fail_a_completed_run() -> None:
    run = result(decode__wrong_type=270, duplicate=2)
    assert FailOnDrops.parse("decode").judge(run)
    assert run.status is RunStatus.FAILED
    assert run.error == (
        "270 messages dropped for reasons decode (--fail-on-drops): decode.wrong_type 270"
    )
    data = results_dict(run)
    assert data["status"] == "failed"
    assert data["fail_on_drops"] == ["decode"]
    assert data["failing_drops"] == {"decode.wrong_type": 270}
    table = summary_table(run)
    assert "FAILED" in table.splitlines()[0]
    assert "(270 dropped: the run failed)" in table


def test_drops_for_other_reasons_leave_the_run_as_it_was() -> None:
    run = result(duplicate=2)
    assert not FailOnDrops.parse("decode").judge(run)
    assert run.status is RunStatus.COMPLETED
    assert run.error is None
    assert results_dict(run)["fail_on_drops"] == ["decode"]
    assert results_dict(run)["failing_drops"] == {}
    assert "(none dropped: passed)" in summary_table(run)


def test_a_timed_out_run_fails_and_a_failed_run_keeps_its_error() -> None:
    timed_out = result(RunStatus.TIMED_OUT, queue_full=1)
    assert FailOnDrops().judge(timed_out)
    assert timed_out.status is RunStatus.FAILED
    assert timed_out.error is not None
    assert timed_out.error.startswith("1 message dropped for any reason")
    failed = result(RunStatus.FAILED, queue_full=1)
    failed.error = "robot 3 Task(L3) raised ValueError"
    assert FailOnDrops().judge(failed)
    assert failed.error == "robot 3 Task(L3) raised ValueError"
    assert failed.failing_drops == {"queue_full": 1}


def test_an_interrupted_run_stays_interrupted() -> None:
    run = result(RunStatus.INTERRUPTED, duplicate=5)
    assert not FailOnDrops().judge(run)
    assert run.status is RunStatus.INTERRUPTED


def test_without_a_policy_results_say_null() -> None:
    run = result(duplicate=5)
    assert results_dict(run)["fail_on_drops"] is None
    assert "fail on drops" not in summary_table(run)
