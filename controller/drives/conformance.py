"""What ``heliotrack protocol conformance`` reports, for every backend: one record per rule
of the drive protocol (:mod:`.modbus.conformance`, :mod:`.canopen.conformance`)."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass

PASS, FAIL, WARN, SKIP = "pass", "FAIL", "warn", "skip"


@dataclass(frozen=True)
class Check:
    """One rule's outcome: ``PASS``, ``FAIL``, ``WARN`` (works, not as recommended) or
    ``SKIP`` (needs ``may_move``, or does not apply to this drive)."""

    name: str
    outcome: str
    detail: str


def refused(name: str, code: int | None, want: int, what: str = "exception") -> Check:
    """The check of a request the drive must refuse with ``want`` (``code``: what it
    answered, None when it took the request)."""
    if code == want:
        return Check(name, PASS, f"{what} {want:#x}" if want > 255 else f"{what} {want}")
    got = "taken" if code is None else (f"{what} {code:#x}" if code > 255 else f"{what} {code}")
    return Check(
        name, FAIL, f"{got}, {what} {want:#x} expected" if want > 255 else f"{got}, {what} {want} expected"
    )


async def in_order(
    static: AsyncIterator[Check],
    moving: Callable[[], AsyncIterator[Check]],
    moving_names: Sequence[str],
    may_move: bool,
) -> AsyncIterator[Check]:
    """The checks that move nothing, then those that do, or a skip for each of them."""
    async for check in static:
        yield check
    if may_move:
        async for check in moving():
            yield check
    else:
        for name in moving_names:
            yield Check(name, SKIP, "moves the axes: --may-move")
