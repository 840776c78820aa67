"""Ctrl-C as a request to stop at the next cycle rather than as a cancellation.

``asyncio.run`` turns SIGINT into a cancellation of the main task.  On Python 3.11
``asyncio.wait_for`` drops a cancellation that arrives as the awaited call completes
(CPython gh-86296, fixed in 3.12), and pymodbus waits that way for every response, so a
Ctrl-C in the middle of a run was now and then lost and the run went on to its end.  A
flag that the loop reads at each cycle cannot be lost.
"""

from __future__ import annotations

import asyncio
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

_noted = threading.Event()


@contextmanager
def stop_on_sigint(stop: asyncio.Event) -> Iterator[None]:
    """Within the block, the first SIGINT sets ``stop`` and a second one cancels the
    current task (as asyncio does by default, for a run that does not stop).

    Enter it from a coroutine running in the main thread.  Where signals cannot be
    handled by the loop (another thread, another platform), SIGINT keeps asyncio's default.
    """
    loop = asyncio.get_running_loop()
    task = asyncio.current_task()

    def on_sigint() -> None:
        if stop.is_set() and task is not None:
            task.cancel()
        stop.set()

    try:
        loop.add_signal_handler(signal.SIGINT, on_sigint)
    except (NotImplementedError, RuntimeError, ValueError):
        yield
        return
    try:
        yield
    finally:
        loop.remove_signal_handler(signal.SIGINT)


async def sleep_unless(stop: asyncio.Event, seconds: float) -> None:
    """Sleep ``seconds`` (s), or until ``stop`` is set if that comes first."""
    try:
        async with asyncio.timeout(seconds):
            await stop.wait()
    except TimeoutError:
        pass


@contextmanager
def sigint_noted() -> Iterator[None]:
    """Within the block, SIGINT raises KeyboardInterrupt as by default and is also noted, so
    that :func:`raise_if_interrupted` raises it again where Python swallowed it: one that
    lands in a finaliser or a garbage-collector callback (matplotlib's figures have them)
    is printed as "Exception ignored" and the program runs on, so Ctrl-C during a report
    had now and then been lost.  Only in the main thread with the default handler in place;
    elsewhere the block changes nothing."""
    if threading.current_thread() is not threading.main_thread() or (
        signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield
        return

    def on_sigint(signum, frame):
        _noted.set()
        raise KeyboardInterrupt

    _noted.clear()
    signal.signal(signal.SIGINT, on_sigint)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        _noted.clear()


def raise_if_interrupted() -> None:
    """Raise KeyboardInterrupt if a SIGINT was noted by :func:`sigint_noted`."""
    if _noted.is_set():
        raise KeyboardInterrupt
