"""A stand-alone CiA 402 master: canopen's own BaseNode402 over an slcan adapter.

Run in its own process by the acceptance test::

    python -m tests.hil.canopen.master_402 PTY EDS NODE_ID TARGET_DEG

It opens the pty with python-can's ``slcan`` interface (as it would a USB-CAN adapter),
loads the exported EDS, drives the node to OPERATION ENABLED in profile position mode,
sends one set-point with the new-set-point handshake and waits until the axis reports
"target reached" there.  The last stdout line is a JSON report; exit status 0 on success.
It imports nothing of heliotrack: it is what a third-party master would do.
"""

from __future__ import annotations

import json
import sys
import time

import canopen

MASTER_HEARTBEAT_COB = 0x700 + 0x7F
SCALE_DEG = 0.001  # 0x607A / 0x6064 units, from the EDS comments / docs


def main(argv: list[str]) -> int:
    pty, eds_path, node_id, target_deg = argv[0], argv[1], int(argv[2]), float(argv[3])
    report: dict = {"ok": False}
    network = canopen.Network()
    network.connect(interface="slcan", channel=pty, sleep_after_open=0, bitrate=500000)
    beat = network.send_periodic(MASTER_HEARTBEAT_COB, b"\x05", 0.2)
    try:
        node = canopen.BaseNode402(node_id, eds_path)
        network.add_node(node)
        report["device_type"] = node.sdo[0x1000].raw
        report["product_code"] = node.sdo[0x1018][2].raw
        # Our heartbeat is running: now ask the drive to watch it (1 s), so it stows if
        # this master dies.
        node.sdo[0x1016][1].raw = (0x7F << 16) | 1000
        report["consumer_heartbeat"] = node.sdo[0x1016][1].raw
        node.nmt.state = "PRE-OPERATIONAL"
        node.setup_402_state_machine()  # reads the PDO mapping by SDO
        node.nmt.state = "OPERATIONAL"
        node.op_mode = "PROFILED POSITION"
        node.state = "OPERATION ENABLED"
        report["state"] = node.state
        report["op_mode"] = node.op_mode
        raw = round(target_deg / SCALE_DEG)
        node.rpdo[1]["Target position"].raw = raw
        node.controlword = 0x3F  # enable + new set-point + immediately
        deadline = time.monotonic() + 1.0
        while not node.statusword & (1 << 12):  # set-point acknowledge
            if time.monotonic() > deadline:
                raise RuntimeError("set-point not acknowledged")
            node.check_statusword()
        node.controlword = 0x0F
        deadline = time.monotonic() + 20.0
        while True:
            sw = node.check_statusword()
            pos = node.tpdo_values.get(0x6064, 0) * SCALE_DEG
            if sw & (1 << 10) and abs(pos - target_deg) < 0.05:
                break
            if time.monotonic() > deadline:
                raise RuntimeError(f"target not reached: position {pos} deg, statusword {sw:#06x}")
        report.update(
            ok=True, position_deg=pos, statusword=sw, sdo_position_deg=node.sdo[0x6064].raw * SCALE_DEG
        )
    except Exception as exc:  # noqa: BLE001 - reported, not raised: the test prints the report
        report["error"] = f"{type(exc).__name__}: {exc}"
    finally:
        beat.stop()
        network.disconnect()
    print(json.dumps(report), flush=True)
    return 0 if report["ok"] else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
