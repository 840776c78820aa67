"""The one retry policy of the drive links."""

import asyncio

import pytest

from controller.drives import DriveCommError, LinkStats
from controller.drives.retry import RetryPolicy


class Flaky(Exception):
    pass


class Refused(Exception):
    pass


def attempts(*outcomes):
    """An attempt function that raises or returns the given outcomes in turn."""
    calls = []

    async def attempt():
        outcome = outcomes[len(calls)]
        calls.append(outcome)
        if isinstance(outcome, BaseException):
            raise outcome
        return outcome

    return attempt, calls


def run(policy, attempt):
    stats = LinkStats()
    result = asyncio.run(policy.run(attempt, what="state read", label="node 7", stats=stats))
    return result, stats


POLICY = RetryPolicy(retries=2, retry_on=(Flaky,), final=(Refused,))


def test_a_retried_error_then_success_counts_every_attempt():
    attempt, calls = attempts(Flaky("timeout"), "ok")
    result, stats = run(POLICY, attempt)
    assert result == "ok" and len(calls) == 2
    assert (stats.transactions, stats.errors, stats.retries) == (2, 1, 1)
    assert len(stats.latencies_s) == 1


def test_attempts_run_out_with_the_last_error_named():
    attempt, calls = attempts(Flaky("a"), Flaky("b"), Flaky("c"), "never")
    with pytest.raises(DriveCommError, match=r"^node 7: state read failed after 3 attempt\(s\): c$"):
        run(POLICY, attempt)
    assert len(calls) == 3


def test_a_final_error_ends_at_once():
    attempt, calls = attempts(Flaky("timeout"), Refused("exception 2"), "never")
    stats = LinkStats()
    with pytest.raises(DriveCommError, match="state read refused by the drive: exception 2"):
        asyncio.run(POLICY.run(attempt, what="state read", label="node 7", stats=stats))
    assert len(calls) == 2
    assert (stats.transactions, stats.errors, stats.retries) == (2, 2, 1)


def test_other_errors_are_not_the_links_business():
    attempt, calls = attempts(KeyError("bug"), "never")
    with pytest.raises(KeyError):
        run(POLICY, attempt)
    assert len(calls) == 1


def test_no_retries_means_one_attempt():
    attempt, calls = attempts(Flaky("timeout"), "never")
    with pytest.raises(DriveCommError, match=r"after 1 attempt\(s\)"):
        run(RetryPolicy(0, retry_on=(Flaky,)), attempt)
    assert len(calls) == 1
