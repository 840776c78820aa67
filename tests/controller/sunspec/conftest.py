"""Fixtures of the SunSpec tests: servers on 127.0.0.1 that stop with the test."""

from __future__ import annotations

import pytest

from controller.sunspec import SunSpecServer

HOST = "127.0.0.1"


def server_starter(**defaults):
    """``(start, servers)``: ``start(plant, **kw)`` serves ``plant`` on a free port (``kw``
    over ``defaults``); ``servers`` lists them, to stop."""
    servers: list[SunSpecServer] = []

    def start(plant, **kw):
        srv = SunSpecServer(plant, plant.on_override, host=HOST, port=0, **{**defaults, **kw}).start()
        servers.append(srv)
        return srv

    return start, servers


@pytest.fixture
def serve():
    start, servers = server_starter()
    yield start
    for srv in servers:
        srv.stop()
