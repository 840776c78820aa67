"""Acceptance, shortened: ``heliotrack run`` against three standalone emulators in other
processes (Modbus RTU on a pty, Modbus TCP, CANopen over slcan) with a video file as the
camera; SIGTERM leaves every axis at its safe position (read from the emulators, not the
controller); after ``kill -9`` the drives' own watchdog stows them; ``check`` rows.

The tests share one plant and run in order (the last one stops an emulator).
"""

from __future__ import annotations

import json
import re
import signal
import threading
import time

import pytest
from pymodbus.client import ModbusTcpClient

from firmware_protocol import Mode, Status
from heliotrack.cli import main
from tests.heliotrack.plant_emulators import Plant as PlantProcs
from tests.heliotrack.plant_emulators import (
    daytime_site,
    heliotrack,
    plant_toml,
    read_axes,
    ready,
    render_video,
    start_drive,
    wait_for,
)

PERIOD_S, HEARTBEAT_S = 1.0, 3.0
# this module's tests run in order on one worker (`make test`: --dist loadscope): the kill -9
# test resumes the stows that the graceful shutdown before it recorded (on a worker of its
# own it had none: a fresh clone's CI, 2026-12-03)


@pytest.fixture(scope="module")
def plant(tmp_path_factory):
    """(emulators, plant file, state folder)."""
    started = {
        "dual-1": start_drive("rtu", 1, 2),
        "row-tcp": start_drive("tcp", 2, 1),
        "row-can": start_drive("canopen", 20, 1),
    }
    folder = tmp_path_factory.mktemp("plant")
    try:
        t = time.time()
        site = daytime_site(t)
        # the camera: frames of the sky from about when the first run opens the file
        video = render_video(folder / "camera.avi", t + 10, frames=3, dt=8.0, site=site)
        procs = PlantProcs({name: ready(d) for name, d in started.items()})
        cfg = plant_toml(
            folder / "plant.toml",
            procs,
            site,
            period=PERIOD_S,
            heartbeat=HEARTBEAT_S,
            video=video,
            sunspec=True,
        )
        yield procs, cfg, folder / "state"
    finally:
        for d in started.values():
            d.stop()


class Run:
    """``heliotrack run`` in a process of its own; its log lines collected as they come."""

    def __init__(self, cfg, state):
        self.proc = heliotrack("run", "--config", str(cfg), "--state", str(state))
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stderr:
            self.lines.append(line.rstrip("\n"))

    def wait_line(self, pattern: str, timeout: float = 40.0) -> str:
        rx = re.compile(pattern)
        found = wait_for(lambda: next((ln for ln in self.lines if rx.search(ln)), None), timeout, 0.05)
        assert found, f"no line matching {pattern!r} in:\n" + "\n".join(self.lines[-30:])
        return found

    def text(self) -> str:
        self._reader.join(5)
        return "\n".join(self.lines)


def test_check_prints_a_row_per_device_all_ok(plant, capsys):
    _, cfg, _ = plant
    assert main(["check", "--config", str(cfg)]) == 0
    out = capsys.readouterr().out
    rows = {ln.split()[0]: ln for ln in out.splitlines()[1:-1]}
    assert set(rows) == {"dual-1", "row-tcp", "row-can", "camera"}, out
    for row in rows.values():
        assert " ok " in row, row
    assert "2 axes; protocol 1.0, firmware 1.0" in rows["dual-1"]
    assert "slcan:/dev/" in rows["row-can"] and "1 axis" in rows["row-can"]
    assert "frame 1280x1024" in rows["camera"]
    assert out.splitlines()[-1] == "4 of 4 device(s) ok"
    # what the drives hold now, and what run will write over it (an audit's finding: the
    # integrator saw neither the watchdog nor the limits)
    assert (
        "watchdog 10 s; limits [0, 360] / [0, 90] deg; stow 180 / 90 deg; speed 10 / 10 deg/s;"
        " run writes watchdog 3 s" in rows["dual-1"]
    )
    assert "watchdog 10 s on node 127; limits [-60, 60] deg" in rows["row-can"]
    assert rows["row-tcp"].endswith("run writes watchdog 3 s, axis 0 soft limits [-55, 55]"), out


def test_run_tracks_then_sigterm_leaves_every_axis_safe(plant):
    procs, cfg, state = plant
    run = Run(cfg, state)
    try:
        served = run.wait_line(r"SunSpec model 601 served on 127.0.0.1:\d+")
        run.wait_line(r"cycle 4: ")
        # SCADA reads the plant meanwhile
        scada = ModbusTcpClient("127.0.0.1", port=int(served.rsplit(":", 1)[1]), timeout=1)
        assert scada.connect()
        assert scada.read_holding_registers(40000, count=2, device_id=1).registers == [0x5375, 0x6E53]
        scada.close()
        # the drives follow the sun: the TCP row (TCP admits a second master) left its stow (0)
        row = read_axes(procs.drives["row-tcp"])[0]
        assert row.mode == Mode.AUTO and abs(row.target_deg) > 0.5, row
        t_kill = time.monotonic()
        run.proc.send_signal(signal.SIGTERM)
        assert run.proc.wait(10) == 0
        exit_s = time.monotonic() - t_kill
    finally:
        if run.proc.poll() is None:
            run.proc.kill()
    log = run.text()
    assert exit_s < 5.0, log
    cycles = [ln for ln in log.splitlines() if re.search(r" cycle \d+: ", ln)]  # not a warning about cycles
    assert len(cycles) >= 4 and all("; 0 error(s)" in ln for ln in cycles), log
    assert any("sun observed" in ln and "camera found" in ln for ln in cycles), (
        log
    )  # the camera fed the filter
    assert "safe position confirmed for 3 of 3 drives" in log and "Traceback" not in log
    # what the emulators say, through their own protocols
    for name in ("dual-1", "row-can"):  # safe_position = "stow"
        axes = read_axes(procs.drives[name])
        assert all(a.mode == Mode.STOW and not a.status & Status.COMM_LOST for a in axes), (name, axes)
    hold = float(re.search(r"row-tcp: holding at (-?[\d.]+) deg", log).group(1))
    row = read_axes(procs.drives["row-tcp"])[0]  # safe_position = "hold"
    assert row.mode == Mode.AUTO and row.target_deg == pytest.approx(hold, abs=0.011)
    row = wait_for(lambda: (a := read_axes(procs.drives["row-tcp"])[0]).status & Status.AT_TARGET and a, 5)
    assert row and row.actual_deg == pytest.approx(hold, abs=0.1)
    # learned state saved; the stows it commanded recorded for the next start
    from controller.store import Store

    store = Store(state / "heliotrack.sqlite")
    try:
        assert store.get_state("sunpath") is not None  # what the filter learned, in the store
    finally:
        store.close()
    assert set(json.loads((state / "shutdown.json").read_text())["stowed"]) == {"dual-1", "row-can"}


def test_after_kill_9_the_drives_watchdog_stows_them(plant, tmp_path):
    procs, cfg, state = plant
    # the same plant on the ephemeris (the hotspot estimator takes seconds to build)
    site = (
        float(re.search(r"latitude = (\S+)", cfg.read_text()).group(1)),
        float(re.search(r"longitude = (\S+)", cfg.read_text()).group(1)),
    )
    cfg = plant_toml(tmp_path / "plant.toml", procs, site, period=PERIOD_S, heartbeat=HEARTBEAT_S)
    run = Run(cfg, state)
    try:
        run.wait_line(r"resuming 2 tracker\(s\) the last shutdown stowed")
        run.wait_line(r"cycle 2: TRACK x3")
        run.proc.kill()
        t_kill = time.monotonic()
        run.proc.wait(5)
    finally:
        if run.proc.poll() is None:
            run.proc.kill()

    def all_stowed() -> bool:
        return all(
            a.mode == Mode.STOW and a.status & Status.COMM_LOST
            for d in procs.drives.values()
            for a in read_axes(d)
        )

    log = run.text()
    assert "left stowed" not in log, log  # the stows of the last shutdown were resumed
    assert wait_for(all_stowed, HEARTBEAT_S + 3.0, 0.1), log
    # the watchdog fired within its timeout of the last heartbeat (reads take ~0.1-0.3 s)
    assert time.monotonic() - t_kill <= HEARTBEAT_S + 1.0


def test_check_with_an_emulator_stopped_names_it(plant, capsys, tmp_path):
    procs, cfg, _ = plant
    text = cfg.read_text()
    text += '\n[[trackers]]\nname = "ghost"\ntype = "single-axis"\nlink = "rs485"\ndevice_id = 7\n'
    ghost = tmp_path / "plant.toml"
    ghost.write_text(text)
    procs.drives["row-tcp"].stop()
    assert main(["check", "--config", str(ghost)]) == 1
    out = capsys.readouterr().out
    rows = {ln.split()[0]: ln for ln in out.splitlines()[1:-1]}
    port = procs.drives["row-tcp"].address
    assert "FAILED" in rows["row-tcp"] and f"127.0.0.1:{port}" in rows["row-tcp"], out
    rtu = procs.drives["dual-1"].address
    assert f"no answer on {rtu} id 7 after 3 tries" in rows["ghost"], out
    assert " ok " in rows["dual-1"] and " ok " in rows["row-can"]
    # the runs before configured the drives: they hold what the plant file says
    assert rows["row-can"].endswith(
        "watchdog 3 s on node 127; limits [-55, 55] deg; stow 0 deg; speed 10 deg/s (as the plant file has it)"
    ), out
    assert out.splitlines()[-1] == "3 of 5 device(s) ok; 2 failed"
