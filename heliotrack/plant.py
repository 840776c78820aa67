"""Generated plant layouts for benchmarks and tests: many rows, one controller."""

from __future__ import annotations

import numpy as np

from controller.config import Config, parse_config


def plant_config(
    n_rows: int,
    ports: list[int] | None = None,
    period_s: float = 1.0,
    heartbeat_timeout_s: float = 15.0,
    seed: int = 1,
    link_kind: str = "modbus-tcp",
    channel: str = "hil",
) -> Config:
    """A site with ``n_rows`` single-axis rows.

    ``link_kind`` "modbus-tcp": each row on its own TCP endpoint on 127.0.0.1 (``ports``);
    "canopen": all rows on one python-can ``virtual`` bus ``channel``, node ids 1..n, PDO
    mapping from the EDS.  Rows differ in cross-axis slope and ground coverage ratio, as
    on rolling terrain.
    """
    rng = np.random.default_rng(seed)
    data = {
        "site": {"name": "plant", "latitude": 32.4835, "longitude": 48.3364},
        "control": {"period_s": period_s, "heartbeat_timeout_s": heartbeat_timeout_s},
        "links": (
            [
                {
                    "name": "can0",
                    "kind": "canopen",
                    "interface": "virtual",
                    "channel": channel,
                    "timeout_s": 0.5,
                    "pdo_mapping": "eds",
                }
            ]
            if link_kind == "canopen"
            else [
                {
                    "name": f"l{i}",
                    "kind": "modbus-tcp",
                    "host": "127.0.0.1",
                    "tcp_port": int(p),
                    "timeout_s": 0.8,
                    "retries": 0,
                }
                for i, p in enumerate(ports or [])
            ]
        ),
        "trackers": [
            {
                "name": f"row-{i}",
                "type": "single-axis",
                "link": "can0" if link_kind == "canopen" else f"l{i}",
                "device_id": i + 1 if link_kind == "canopen" else 1,
                "gcr": float(rng.uniform(0.3, 0.5)),
                "cross_axis_tilt": float(rng.uniform(-5, 5)),
            }
            for i in range(n_rows)
        ],
    }
    return parse_config(data, "<plant benchmark>")
