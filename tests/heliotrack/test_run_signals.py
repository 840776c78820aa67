"""``run``'s stop signals: a repeat within a second is the same stop, a later one exits."""

import asyncio
import signal

from heliotrack.commands import run as run_cmd


def test_a_signal_repeated_at_once_is_the_same_stop_and_a_later_one_exits(monkeypatch):
    svc = run_cmd.Service(None, None)
    svc.stop = asyncio.Event()
    exits: list[int] = []
    monkeypatch.setattr(run_cmd.os, "_exit", lambda code: exits.append(code))
    svc._on_signal(signal.SIGTERM)
    svc._on_signal(signal.SIGTERM)  # ``timeout`` / a supervisor: the group signalled too
    assert svc.stop.is_set() and svc.stopped_by == "SIGTERM" and exits == []
    svc._first_signal -= run_cmd.REPEAT_S + 0.1  # the operator, a moment later
    svc._on_signal(signal.SIGINT)
    assert exits == [128 + signal.SIGINT]
