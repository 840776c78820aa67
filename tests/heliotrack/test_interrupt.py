"""Ctrl-C inside an asyncio run: a flag at the first SIGINT, a cancellation at the second."""

import asyncio
import os
import signal
import time

from heliotrack.interrupt import sleep_unless, stop_on_sigint


def test_the_first_sigint_sets_the_flag_and_the_second_cancels():
    async def main() -> tuple[bool, bool]:
        stop = asyncio.Event()
        with stop_on_sigint(stop):
            os.kill(os.getpid(), signal.SIGINT)
            await asyncio.wait_for(stop.wait(), 5)  # a flag, not a KeyboardInterrupt
            first = stop.is_set()
            os.kill(os.getpid(), signal.SIGINT)
            try:
                await asyncio.sleep(5)
            except asyncio.CancelledError:
                return first, True
        return first, False

    assert asyncio.run(main()) == (True, True)
    # the handler is gone after the block: SIGINT is Python's KeyboardInterrupt again
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_the_pacing_sleep_ends_when_the_flag_is_set():
    async def main() -> float:
        stop = asyncio.Event()
        asyncio.get_running_loop().call_later(0.05, stop.set)
        t0 = time.monotonic()
        await sleep_unless(stop, 30.0)
        return time.monotonic() - t0

    assert asyncio.run(main()) < 5.0


def test_the_sleep_lasts_its_time_without_the_flag():
    async def main() -> float:
        t0 = time.monotonic()
        await sleep_unless(asyncio.Event(), 0.1)
        return time.monotonic() - t0

    assert asyncio.run(main()) >= 0.09
