"""SunSpec poll latency as a SCADA client sees it, measured with pysunspec2."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from controller.sunspec.models import TRACKER_MODEL_ID


@dataclass(frozen=True)
class PollLatency:
    """Result of :func:`poll_latency`; times in seconds.

    ``read_*`` are per full read of model 601 (all trackers, in as many 125-register
    requests as pysunspec2 needs).
    """

    host: str
    port: int
    n_trackers: int
    registers: int  # model 601 length L + 2
    scan_s: float  # connect + scan (marker search, models 1 and 601, end)
    n: int
    read_p50_s: float
    read_p99_s: float
    read_max_s: float
    read_mean_s: float

    def summary(self) -> str:
        return (
            f"SunSpec poll {self.host}:{self.port}: {self.n_trackers} trackers "
            f"({self.registers} registers), scan {self.scan_s * 1e3:.1f} ms, "
            f"model 601 read p50 {self.read_p50_s * 1e3:.2f} ms, "
            f"p99 {self.read_p99_s * 1e3:.2f} ms, max {self.read_max_s * 1e3:.2f} ms (n={self.n})"
        )


def poll_latency(
    host: str, port: int, n: int = 100, *, device_address: int = 1, timeout_s: float = 5.0
) -> PollLatency:
    """Scan a SunSpec server once with pysunspec2, then read model 601 ``n`` times.

    Parameters
    ----------
    host, port : str, int
        The server (the benchmark runs it on 127.0.0.1).
    n : int
        Number of timed full reads of model 601 over one connection.
    device_address : int
        Modbus unit id.
    timeout_s : float
        Per-request timeout, seconds.

    Returns
    -------
    PollLatency
    """
    # imported here so the controller does not pay for the client unless benchmarking
    from sunspec2.modbus.client import SunSpecModbusClientDeviceTCP

    dev = SunSpecModbusClientDeviceTCP(slave_id=device_address, ipaddr=host, ipport=port, timeout=timeout_s)
    try:
        t0 = time.perf_counter()
        dev.scan()
        scan_s = time.perf_counter() - t0
        if TRACKER_MODEL_ID not in dev.models:
            raise RuntimeError(
                f"{host}:{port} serves no model 601 (found {sorted(k for k in dev.models if isinstance(k, int))})"
            )
        model = dev.models[TRACKER_MODEL_ID][0]
        dev.connect()
        times = np.empty(n)
        for k in range(n):
            t = time.perf_counter()
            model.read()
            times[k] = time.perf_counter() - t
    finally:
        dev.close()
    return PollLatency(
        host,
        port,
        int(model.N.value),
        int(model.len) + 2,
        scan_s,
        n,
        float(np.percentile(times, 50)),
        float(np.percentile(times, 99)),
        float(times.max()),
        float(times.mean()),
    )
