"""Many emulated row drives in one process, each its own Modbus TCP endpoint on 127.0.0.1.

A plant has one drive (row controller) per row, each with its own address; this runs N of
them on one asyncio loop, on the wall clock, for the plant benchmark and tests.  Rows can
be killed one by one to test fault isolation.

``python -m hil.plant --rows N`` prints one JSON line ``{"ports": [...]}`` and then
obeys stdin lines ``kill I`` (stop row I's server) and ``quit``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import threading
import time

from pymodbus.server import ModbusTcpServer

from .drive import AxisParams, DriveFirmware
from .modbus_device import MultidropCore, sim_device


def row_firmware(now=time.time, max_angle: float = 55.0) -> DriveFirmware:
    return DriveFirmware(
        [
            AxisParams(
                soft_min=-max_angle, soft_max=max_angle, hard_min=-max_angle - 5, hard_max=max_angle + 5
            )
        ],
        now,
        heartbeat_timeout=0,
    )


class RowFarm:
    """N single-axis row drives served on 127.0.0.1 from one event loop (in a thread)."""

    def __init__(self, n: int, device_id: int = 1, now=time.time):
        self.firmwares = [row_firmware(now) for _ in range(n)]
        self.device_id = device_id
        self.servers: list[ModbusTcpServer] = []
        self.ports: list[int] = []
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="row-farm")

    def start(self) -> RowFarm:
        self._thread.start()
        if not self._ready.wait(60):
            raise RuntimeError("row farm did not start")
        return self

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        self._loop.run_until_complete(self._start_all())
        self._ready.set()
        self._loop.run_forever()

    async def _start_all(self) -> None:
        for fw in self.firmwares:
            dev = sim_device(self.device_id, fw)
            srv = ModbusTcpServer([dev], address=("127.0.0.1", 0), ignore_missing_devices=True)
            srv.context = MultidropCore([dev])
            await srv.serve_forever(background=True)
            self.servers.append(srv)
            listener = srv.transport  # a TCP server's transport is the asyncio.Server
            self.ports.append(listener.sockets[0].getsockname()[1])  # type: ignore[attr-defined]

    def kill(self, i: int) -> None:
        """Stop row ``i``'s server and drop its connections: the row goes silent."""
        fut = asyncio.run_coroutine_threadsafe(self.servers[i].shutdown(), self._loop)
        fut.result(10)

    def stop(self) -> None:
        async def all_down():
            for s in self.servers:
                await s.shutdown()
            # Requests still being answered late (fault injection) die with the farm.
            pending = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for t in pending:
                t.cancel()
            await asyncio.gather(*pending, return_exceptions=True)

        if self._loop.is_running():
            asyncio.run_coroutine_threadsafe(all_down(), self._loop).result(30)
            self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(10)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m hil.plant")
    p.add_argument("--rows", type=int, required=True)
    args = p.parse_args(argv)
    farm = RowFarm(args.rows).start()
    print(json.dumps({"ports": farm.ports}), flush=True)
    for line in sys.stdin:
        cmd = line.split()
        if cmd[:1] == ["kill"] and len(cmd) == 2:
            farm.kill(int(cmd[1]))
            print(json.dumps({"killed": int(cmd[1])}), flush=True)
        elif cmd[:1] == ["quit"]:
            break
    farm.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
