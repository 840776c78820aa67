"""One heliotrack process per shared bus: a Modbus TCP endpoint or a CAN channel can be
opened by any number of processes, so a trial ``run`` with another ``--state`` or a
``check`` beside the service (it writes each drive's configuration) had driven the same
drives at once (an installer's walk).  They are refused in one line naming the first."""

from __future__ import annotations

import os
import signal
import socket

import pytest

from controller.drives.links import CanopenLink, ModbusRtuLink, ModbusTcpLink
from controller.errors import UserError
from heliotrack.bus_claims import claim_buses, lock_path, shared_buses
from heliotrack.cli import main
from tests.heliotrack.plant_emulators import heliotrack
from tests.heliotrack.test_run_faults import _silent_plant


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def tcp_plant(folder, port: int):
    """test_run_faults' silent plant, its line a Modbus TCP gateway where nobody listens."""
    p = _silent_plant(folder, "unused")
    text = p.read_text().replace(
        'kind = "modbus-rtu"\nport = "unused"', f'kind = "modbus-tcp"\nhost = "127.0.0.1"\ntcp_port = {port}'
    )
    p.write_text(
        text.replace('name = "rs485"', 'name = "gateway"').replace('link = "rs485"', 'link = "gateway"')
    )
    return p


def test_check_and_a_second_run_beside_a_run_on_a_tcp_gateway_are_refused(tmp_path, capsys):
    cfg = tcp_plant(tmp_path, free_port())  # nobody listens: run goes on probing the link
    first = heliotrack("run", "--config", str(cfg), "--state", str(tmp_path / "service"))
    try:
        assert "heliotrack run:" in first.stderr.readline()
        assert main(["check", "--config", str(cfg)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("heliotrack: error: link 'gateway': 127.0.0.1:") and (
            f"is driven by another heliotrack process (pid {first.pid})" in err
        ), err
        assert main(["run", "--config", str(cfg), "--state", str(tmp_path / "trial"), "--duration", "1"]) == 2
        assert f"(pid {first.pid})" in capsys.readouterr().err
        assert first.poll() is None  # the service is left alone
        first.send_signal(signal.SIGTERM)
        first.wait(10)
    finally:
        if first.poll() is None:
            first.kill()
    # the service gone, the bus is free (its lock file stays, unlocked)
    assert main(["check", "--config", str(cfg)]) == 1  # nobody answers: a verdict, not a refusal
    assert "driven by another" not in capsys.readouterr().err


def test_which_buses_are_claimed():
    links = [
        ModbusRtuLink(name="rs485", port="/dev/ttyUSB0"),  # pyserial holds the port itself
        ModbusTcpLink(name="gw", host="10.0.0.5", tcp_port=502),
        ModbusTcpLink(name="gw-again", host="10.0.0.5", tcp_port=502),  # one gateway, two links
        CanopenLink(name="can", interface="socketcan", channel="can0"),
        CanopenLink(name="virtual", interface="virtual", channel="x"),  # in-process only
    ]
    assert shared_buses(links) == {("tcp", "10.0.0.5", "502"): "gw", ("can", "can0"): "can"}
    assert lock_path(("tcp", "10.0.0.5", "502")).name == "heliotrack-tcp-10.0.0.5-502.lock"
    with claim_buses(links):
        with pytest.raises(UserError, match=r"link 'can': CAN channel can0 is driven by another"):
            with claim_buses(links[3:]):
                pass
    with claim_buses(links):  # let go at the end of the block
        pass


def test_a_lock_folder_named_in_the_environment_holds_the_locks(tmp_path, monkeypatch):
    # containers on one host see each other's locks only in a folder they all mount
    folder = tmp_path / "shared" / "locks"  # made when first needed
    monkeypatch.setenv("HELIOTRACK_LOCK_DIR", str(folder))
    links = [ModbusTcpLink(name="gw", host="10.0.0.5", tcp_port=502)]
    with claim_buses(links):
        assert (folder / "heliotrack-tcp-10.0.0.5-502.lock").read_text() == f"{os.getpid()}\n"
        with pytest.raises(UserError, match=r"link 'gw': 10.0.0.5:502 is driven by another"):
            with claim_buses(links):
                pass
