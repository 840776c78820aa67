"""One retry policy for every drive link: how many attempts, which errors are worth another
attempt, which are final, and what the link's statistics count.

A backend describes its errors once (a Modbus timeout is retried, a Modbus exception
response "illegal data address" is final; a CANopen SDO timeout is retried, an SDO abort
is final) and runs each transaction through :meth:`RetryPolicy.run`.  Errors in neither
set are not the link's business (a bug, a cancellation) and pass through unchanged.
"""

from __future__ import annotations

import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import TypeVar

from .base import DriveNoAnswer, DriveRefused, LinkStats

T = TypeVar("T")
Errors = tuple[type[BaseException], ...]


@dataclass(frozen=True)
class RetryPolicy:
    """Attempts of one transaction on a drive link.

    Parameters
    ----------
    retries : int
        Extra attempts after a failed one (0: one attempt only).
    retry_on : tuple of exception types
        Failures worth another attempt (no answer, a garbled answer, a busy device).
    final : tuple of exception types
        Failures that another attempt would repeat (the device refused the request); they
        end the transaction at once.  Checked before ``retry_on``.
    """

    retries: int
    retry_on: Errors
    final: Errors = ()

    @property
    def attempts(self) -> int:
        """Attempts at most per transaction."""
        return self.retries + 1

    async def run(self, attempt: Callable[[], Awaitable[T]], *, what: str, label: str, stats: LinkStats) -> T:
        """Run ``attempt()`` until it succeeds, fails finally, or the attempts run out.

        Every attempt counts as a transaction in ``stats``; a failed one as an error, and
        an attempt after a failure as a retry.  The latency (s) of the successful attempt
        is recorded.

        Raises
        ------
        DriveCommError
            ``"<label>: <what> refused by the drive: ..."`` for a final error, or
            ``"<label>: <what> failed after N attempt(s): <last error>"`` (a
            :class:`~controller.drives.base.DriveNoAnswer`).
        """
        last: BaseException | None = None
        for n in range(self.attempts):
            t0 = time.perf_counter()
            stats.transactions += 1
            try:
                result = await attempt()
            except self.final as exc:
                stats.errors += 1
                raise DriveRefused(f"{label}: {what} refused by the drive: {exc}", exc) from None
            except self.retry_on as exc:
                stats.errors += 1
                last = exc
                if n < self.retries:
                    stats.retries += 1
                continue
            stats.latencies_s.append(time.perf_counter() - t0)
            return result
        raise DriveNoAnswer(label, what, self.attempts, last)
