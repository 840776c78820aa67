"""Which devices each command may use, the state folder, the log options, ``hil drive``'s
options, and ``check`` on a port that is not there: one line, never a traceback."""

from __future__ import annotations

import json
import logging
import re
import time
from dataclasses import replace
from pathlib import Path

import pytest

from controller.config import load_config
from controller.errors import ConfigError
from heliotrack.cli import build_parser, main
from heliotrack.logs import logging_configured
from heliotrack.runtime import require_hil, use_state_folder
from heliotrack.scenario import load_scenario
from tests.conftest import DEFAULT_CONFIG

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "config" / "plant-example.toml"


def _variant(tmp_path, old, new, source=EXAMPLE):
    text = source.read_text()
    assert old in text
    p = tmp_path / "plant.toml"
    p.write_text(text.replace(old, new).replace('"calibration/', f'"{REPO}/config/calibration/'))
    return p


def test_the_plant_example_is_valid_and_real():
    cfg = load_config(EXAMPLE)
    assert {link.kind for link in cfg.links} == {"modbus-rtu", "modbus-tcp", "canopen"}
    assert not any(link.is_hil for link in cfg.links) and cfg.hotspot.frames == "device:0"
    assert {t.safe_position for t in cfg.trackers} == {"stow", "hold"}


@pytest.mark.parametrize("command", ["run", "check"])
@pytest.mark.parametrize(
    "old, new, key",
    [
        ('port = "/dev/ttyUSB0"', 'port = "hil"', "links[0].port"),
        ('host = "10.0.0.30"', 'host = "hil"', "links[1].host"),
        ('channel = "can0"', 'channel = "hil"', "links[2].channel"),
        ('frames = "device:0"', 'frames = "hil"', "hotspot.frames"),
    ],
)
def test_run_and_check_refuse_the_simulators_devices(tmp_path, capsys, command, old, new, key):
    p = _variant(tmp_path, old, new)
    assert main([command, "--config", str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"{p}: {key}" in err and "heliotrack simulate" in err, err


def test_validate_opens_the_calibration_bundle_the_plant_file_names(tmp_path, capsys):
    good = _variant(tmp_path, "[hotspot]", "[hotspot]")
    assert main(["config", "validate", str(good)]) == 0
    assert "1 calibration bundle(s)" in capsys.readouterr().out
    bundle = tmp_path / "typo.toml"
    text = (REPO / "config" / "calibration" / "recommended.toml").read_text()
    bundle.write_text(text.replace("[camera]", "[cameras]", 1))
    p = tmp_path / "plant.toml"
    p.write_text(good.read_text().replace(f"{REPO}/config/calibration/recommended.toml", str(bundle)))
    assert main(["config", "validate", str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"{bundle}: cameras" in err, err


def test_validate_points_a_scenario_file_to_the_scenario_flag(capsys):
    assert main(["config", "validate", str(DEFAULT_CONFIG)]) == 2
    assert "validate it with --scenario" in capsys.readouterr().err
    assert main(["config", "validate", "--scenario", str(DEFAULT_CONFIG)]) == 0


def test_run_refuses_a_scenario_file(capsys):
    assert main(["run", "--config", str(DEFAULT_CONFIG)]) == 2
    assert "no [hil] table" in capsys.readouterr().err


@pytest.mark.parametrize(
    "old, new, key",
    [
        ('port = "hil"', 'port = "/dev/ttyUSB0"', "links[0].port"),
        ('host = "hil"', 'host = "10.0.0.30"', "links[1].host"),
        ("tcp_port = 502", "tcp_port = 1502", "links[1].tcp_port"),
        ('channel = "hil"', 'channel = "can0"', "links[2].channel"),
    ],
)
def test_simulate_refuses_real_devices_it_would_ignore(tmp_path, old, new, key):
    mixed = REPO / "config" / "hil-mixed.toml"
    require_hil(load_scenario(mixed))  # the shipped scenario passes
    p = tmp_path / "s.toml"
    p.write_text(mixed.read_text().replace(old, new))
    with pytest.raises(ConfigError, match=r"heliotrack run") as e:
        require_hil(load_scenario(p))
    assert e.value.key == key


def test_the_state_folder_holds_the_learned_state(tmp_path):
    cfg = load_config(EXAMPLE)
    same, none = use_state_folder(cfg, None)
    assert same is cfg and none is None
    got, state = use_state_folder(cfg, tmp_path / "var" / "heliotrack")
    assert state.path.is_dir() and got.sunpath.state == state.path / "sunpath.json"
    assert got.store.path == state.path / "heliotrack.sqlite"
    named = replace(
        cfg,
        sunpath=replace(cfg.sunpath, state=tmp_path / "mine.json"),
        store=replace(cfg.store, path=tmp_path / "mine.sqlite"),
    )
    got = use_state_folder(named, tmp_path / "s")[0]  # what the plant file names wins
    assert (got.sunpath.state, got.store.path) == (tmp_path / "mine.json", tmp_path / "mine.sqlite")
    (tmp_path / "file").write_text("")
    with pytest.raises(ConfigError, match="--state"):
        use_state_folder(cfg, tmp_path / "file" / "sub")
    with pytest.raises(ConfigError) as exc:  # the option named alone, not as a config key
        use_state_folder(cfg, tmp_path / "file")
    assert str(exc.value).startswith("--state: expected a folder (this is a file)")


def test_check_names_a_port_that_is_not_there(tmp_path, capsys):
    p = tmp_path / "plant.toml"
    p.write_text(
        '[site]\nlatitude = 10.0\nlongitude = 20.0\n[[links]]\nname = "rs485"\nkind = "modbus-rtu"\n'
        f'port = "{tmp_path / "ttyUSB9"}"\n[[trackers]]\nname = "row-1"\ntype = "single-axis"\n'
        'link = "rs485"\ndevice_id = 3\n'
    )
    assert main(["check", "--config", str(p)]) == 1
    out, err = capsys.readouterr()
    row = out.splitlines()[1]
    assert row.startswith("row-1") and "FAILED" in row and "ttyUSB9 id 3" in row, out
    assert row.endswith(
        f"{tmp_path / 'ttyUSB9'}: no such device (unplugged, or another name: see /dev/serial/by-id/)"
    )
    assert out.splitlines()[-1] == "0 of 1 device(s) ok; 1 failed" and "Traceback" not in err


def test_log_options_go_before_the_command_and_after_run():
    p = build_parser()
    a = p.parse_args(["--log-level", "debug", "--log-format", "json", "run", "--config", "x.toml"])
    assert (a.log_level, a.log_format, a.log_file, a.default_log_level) == ("DEBUG", "json", None, "INFO")
    a = p.parse_args(["--log-level", "error", "run", "--config", "x.toml", "--log-file", "l.txt"])
    assert (a.log_level, a.log_file) == ("ERROR", Path("l.txt"))  # both places count
    a = p.parse_args(["check", "--config", "x.toml"])
    assert a.log_level is None and a.default_log_level == "WARNING"


def test_json_lines_our_level_and_libraries_at_warning(tmp_path):
    log_file = tmp_path / "run.log"
    root = logging.getLogger()
    level_before, handlers_before = root.level, list(root.handlers)
    with logging_configured("INFO", "json", log_file):
        logging.getLogger("heliotrack.run").info(
            "cycle %d", 7, extra={"fields": {"cycle": 7, "el": float("nan")}}
        )
        logging.getLogger("heliotrack.run").debug("not at INFO")
        logging.getLogger("pymodbus.logging").info("a library's chatter")
        logging.getLogger("pymodbus.logging").warning("a library's warning")  # never silenced
    assert (root.level, root.handlers) == (level_before, handlers_before)  # put back
    lines = [json.loads(line) for line in log_file.read_text().splitlines()]
    assert [(r["logger"], r["level"], r["message"]) for r in lines] == [
        ("heliotrack.run", "INFO", "cycle 7"),
        ("pymodbus.logging", "WARNING", "a library's warning"),
    ]
    assert lines[0]["cycle"] == 7 and lines[0]["el"] is None and lines[0]["time"].endswith("+00:00")


@pytest.mark.parametrize("level, shown", [("INFO", False), ("DEBUG", True)])
def test_pymodbus_timeouts_are_debug_records_and_its_other_errors_stay(tmp_path, level, shown):
    log_file = tmp_path / "run.log"
    with logging_configured(level, "json", log_file):
        lib = logging.getLogger("pymodbus.logging")
        lib.error("No response received after 0 retries, continue with next request\n>>>>> send: 0x0 0x1")
        lib.error("requested device id does not exist: 2")  # a SCADA client's wrong unit id
        lib.error("a library's real error")
    got = [json.loads(line)["message"] for line in log_file.read_text().splitlines()]
    routine = [m for m in got if m.startswith(("No response received", "requested device id"))]
    assert len(routine) == (2 if shown else 0) and "a library's real error" in got


def test_a_log_file_that_cannot_be_written_is_one_line(tmp_path, capsys):
    bad = tmp_path / "missing" / "x.log"
    assert main(["--log-file", str(bad), "config", "validate", str(EXAMPLE)]) == 2
    assert "--log-file" in capsys.readouterr().err


@pytest.mark.parametrize(
    "option, value",
    [
        ("--heartbeat-timeout", "-1"),
        ("--max-speed", "-2"),
        ("--max-speed", "0"),
        # beyond what the drive's own registers hold: every read of them had failed
        ("--heartbeat-timeout", "7000"),
        ("--heartbeat-timeout", "inf"),
        ("--max-speed", "100"),
    ],
)
def test_hil_drive_refuses_a_negative_timeout_or_speed(capsys, option, value):
    assert main(["hil", "drive", option, value]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and option in err and "Traceback" not in err


def test_hil_drive_firmware_counts_its_own_time(monkeypatch):
    """A step of the wall clock neither fires nor delays the standalone drive's watchdog."""
    from heliotrack.commands.hil import firmware

    wall, mono = [1.7e9], [100.0]
    monkeypatch.setattr(time, "time", lambda: wall[0])
    monkeypatch.setattr(time, "monotonic", lambda: mono[0])
    fw = firmware(build_parser().parse_args(["hil", "drive", "--heartbeat-timeout", "2"]))
    wall[0] += 3600.0  # NTP steps the wall clock an hour
    fw.update()
    assert not fw.comm_lost
    mono[0] += 2.5  # 2.5 s of silence on the drive's own clock
    fw.update()
    assert fw.comm_lost


def test_check_reads_the_sensors_on_a_line(tmp_path, capsys):
    """A drive, a pyranometer and an anemometer served on one pty: one row each."""
    from hil.anemometer import Anemometer
    from hil.drive import DriveFirmware
    from hil.modbus_server import ModbusServerThread
    from hil.pty import PtyLink
    from hil.pyranometer import Pyranometer
    from hil.wind import WindScript
    from tests.conftest import two_axes

    devices = {
        1: DriveFirmware(two_axes(), time.time, monotonic=time.monotonic),
        10: Pyranometer(lambda t: 640.0, time.monotonic, seed=1),
        11: Anemometer(WindScript(time.time()), time.monotonic),
    }
    with PtyLink.open() as link, ModbusServerThread(devices, serial_url=link.url):
        p = tmp_path / "plant.toml"
        p.write_text(
            f'[site]\nlatitude = 10.0\nlongitude = 20.0\n[[links]]\nname = "rs485"\nkind = "modbus-rtu"\n'
            f'port = "{link.path}"\n[[trackers]]\nname = "dual-1"\ntype = "dual-axis"\nlink = "rs485"\n'
            'device_id = 1\n[pyranometer]\nlink = "rs485"\ndevice_id = 10\n'
            '[wind]\nlink = "rs485"\ndevice_id = 11\n'
        )
        assert main(["check", "--config", str(p)]) == 0
    out = capsys.readouterr().out
    rows = {ln.split()[0]: ln for ln in out.splitlines()[1:-1]}
    assert set(rows) == {"dual-1", "pyranometer", "anemometer"}, out
    assert f"{link.path} id 10" in rows["pyranometer"] and " W/m2" in rows["pyranometer"], out
    assert f"{link.path} id 11" in rows["anemometer"] and "m/s, gust" in rows["anemometer"], out
    assert "at 180.00, 90.00 deg (AUTO, AUTO)" in rows["dual-1"], out
    # how long the drive takes to answer on this line (the median and the slowest request)
    assert re.search(r"; up \d+ s; rtt \d+(\.\d)? ms \(max \d+(\.\d)? ms\); no fault;", rows["dual-1"]), out


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["protocol", "export", "{f}"], "cannot write"),
        (["protocol", "export", "{f}/sub"], "cannot write"),
        (["config", "docs", "--out", "{d}"], "is a folder"),
        (["config", "docs", "--out", "{f}/x.md"], "cannot write"),
    ],
)
def test_an_output_path_that_cannot_be_written_is_one_line(tmp_path, capsys, argv, needle):
    """An audit's cases: FileExistsError, NotADirectoryError, IsADirectoryError tracebacks."""
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    argv = [a.format(f=tmp_path / "afile", d=tmp_path / "adir") for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and err.count("\n") == 0 and "Traceback" not in err
    assert (tmp_path / "afile").read_text() == "x"


def test_check_names_a_port_that_refuses_its_parity_and_goes_on(tmp_path, capsys):
    """An audit's case: ``parity = "E"`` on a pty (``termios.error``) printed a traceback
    and no further row."""
    from hil.drive import DriveFirmware
    from hil.modbus_server import ModbusServerThread
    from hil.pty import PtyLink
    from tests.conftest import two_axes

    fws = {1: DriveFirmware(two_axes(), time.time, monotonic=time.monotonic)}
    with (
        PtyLink.open() as even,
        PtyLink.open() as plain,
        ModbusServerThread(fws, serial_url=even.url),
        ModbusServerThread({2: DriveFirmware(two_axes(), time.time)}, serial_url=plain.url),
    ):
        p = tmp_path / "plant.toml"
        p.write_text(
            '[site]\nlatitude = 10.0\nlongitude = 20.0\n[[links]]\nname = "a"\nkind = "modbus-rtu"\n'
            f'port = "{even.path}"\nparity = "E"\n[[links]]\nname = "b"\nkind = "modbus-rtu"\n'
            f'port = "{plain.path}"\n'
            '[[trackers]]\nname = "dual-1"\ntype = "dual-axis"\nlink = "a"\ndevice_id = 1\n'
            '[[trackers]]\nname = "dual-2"\ntype = "dual-axis"\nlink = "b"\ndevice_id = 2\n'
        )
        assert main(["check", "--config", str(p)]) == 1
    out, err = capsys.readouterr()
    rows = {ln.split()[0]: ln for ln in out.splitlines()[1:-1]}
    assert set(rows) == {"dual-1", "dual-2"} and "Traceback" not in err, (out, err)
    assert rows["dual-1"].endswith(
        f"FAILED {even.path}: cannot configure the port (baudrate 115200, parity E, stopbits 1): "
        "Invalid argument"
    ), out
    assert " ok " in rows["dual-2"] and out.splitlines()[-1] == "1 of 2 device(s) ok; 1 failed"


def test_an_unexpected_error_of_one_device_is_its_row():
    """Whatever a library raises, the row says so and the rows after it still print."""
    import asyncio

    from heliotrack.commands.check import _guarded

    async def surprise():
        raise KeyError("0x6041")

    row = asyncio.run(_guarded("row-can", "slcan:/dev/ttyACM0 node 20", surprise()))
    assert (row.ok, row.detail) == (False, "unexpected KeyError: '0x6041'")


def test_check_fails_a_drive_in_maintenance_or_with_another_axis_count(tmp_path, capsys):
    """An audit's cases: a drive left in MAINTENANCE (which run never moves) and a
    single-axis row mapped to a two-axis drive (a wrong device_id) were both ok."""
    from firmware_protocol import Mode
    from hil.drive import DriveFirmware
    from hil.modbus_server import ModbusServerThread
    from hil.pty import PtyLink
    from tests.conftest import two_axes

    fws = {i: DriveFirmware(two_axes(), time.time, monotonic=time.monotonic) for i in (1, 2, 3)}
    fws[1]._set_mode(0, Mode.MAINTENANCE)  # a service technician's panel
    one_axis = DriveFirmware(two_axes()[:1], time.time, monotonic=time.monotonic)
    with PtyLink.open() as link, ModbusServerThread({**fws, 4: one_axis}, serial_url=link.url):
        p = tmp_path / "plant.toml"
        p.write_text(
            '[site]\nlatitude = 10.0\nlongitude = 20.0\n[[links]]\nname = "rs485"\nkind = "modbus-rtu"\n'
            f'port = "{link.path}"\n'
            '[[trackers]]\nname = "dual-1"\ntype = "dual-axis"\nlink = "rs485"\ndevice_id = 1\n'
            '[[trackers]]\nname = "row-2"\ntype = "single-axis"\nlink = "rs485"\ndevice_id = 2\n'
            '[[trackers]]\nname = "dual-3"\ntype = "dual-axis"\nlink = "rs485"\ndevice_id = 3\n'
            '[[trackers]]\nname = "dual-4"\ntype = "dual-axis"\nlink = "rs485"\ndevice_id = 4\n'
        )
        assert main(["check", "--config", str(p)]) == 1
    out = capsys.readouterr().out
    rows = {ln.split()[0]: ln for ln in out.splitlines()[1:-1]}
    detail = {name: row.split(" FAILED ", 1)[-1] for name, row in rows.items()}
    assert detail["dual-1"].startswith(
        "axis 0 in MAINTENANCE (local service mode): run will not move it (2 axes;"
    ), out
    assert detail["row-2"].startswith("drive has 2 axes, a single-axis tracker drives 1: wrong device_id?")
    assert " ok " in rows["dual-3"], out
    assert detail["dual-4"].startswith("drive has 1 axis, a dual-axis tracker needs 2: wrong device_id?")
    assert out.splitlines()[-1] == "1 of 4 device(s) ok; 3 failed", out


def test_ctrl_c_during_check_says_how_far_it_got(tmp_path):
    """An audit's case: Ctrl-C exited 130 without a word; the drive being checked (here
    one that does not answer, 5 s a try) is given up at once."""
    import signal

    from hil.drive import DriveFirmware
    from hil.modbus_server import ModbusServerThread
    from hil.pty import PtyLink
    from tests.conftest import two_axes
    from tests.heliotrack.plant_emulators import heliotrack

    fws = {1: DriveFirmware(two_axes(), time.time, monotonic=time.monotonic)}
    with PtyLink.open() as served, PtyLink.open() as silent, ModbusServerThread(fws, serial_url=served.url):
        p = tmp_path / "plant.toml"
        p.write_text(
            '[site]\nlatitude = 10.0\nlongitude = 20.0\n[[links]]\nname = "a"\nkind = "modbus-rtu"\n'
            f'port = "{served.path}"\n[[links]]\nname = "b"\nkind = "modbus-rtu"\nport = "{silent.path}"\n'
            "timeout_s = 5.0\nretries = 0\n"
            '[[trackers]]\nname = "dual-1"\ntype = "dual-axis"\nlink = "a"\ndevice_id = 1\n'
            '[[trackers]]\nname = "dual-2"\ntype = "dual-axis"\nlink = "b"\ndevice_id = 1\n'
        )
        proc = heliotrack("check", "--config", str(p))
        try:
            lines = [proc.stdout.readline(), proc.stdout.readline()]  # the header, dual-1's row
            assert lines[1].startswith("dual-1") and " ok " in lines[1], lines
            time.sleep(0.5)  # dual-2's first try under way
            proc.send_signal(signal.SIGINT)
            t = time.monotonic()
            rc = proc.wait(10)
            waited = time.monotonic() - t
        finally:
            if proc.poll() is None:
                proc.kill()
        rest, err = proc.communicate()
    assert rc == 130 and waited < 3.0, (rc, waited, rest, err)
    assert rest.splitlines() == ["check interrupted: 1 of 2 device(s) checked"], (rest, err)
    assert "Traceback" not in err, err


@pytest.mark.parametrize("level, shown", [("WARNING", False), ("DEBUG", True)])
def test_canopen_sdo_timeouts_are_debug_records_and_its_other_aborts_stay(tmp_path, level, shown):
    """An audit's case: 'ERROR canopen.sdo.client: Transfer aborted by client with code
    0x05040000' in the middle of check's table, for a drive whose row says it already."""
    import canopen
    from canopen.sdo import SdoCommunicationError

    log_file = tmp_path / "check.log"
    with logging_configured(level, "json", log_file):
        network = canopen.Network()
        network.connect(interface="virtual", channel="nobody-answers")
        try:
            node = canopen.RemoteNode(20, canopen.ObjectDictionary())
            network.add_node(node)
            node.sdo.RESPONSE_TIMEOUT = 0.05
            with pytest.raises(SdoCommunicationError):
                node.sdo.upload(0x1000, 0)  # nobody on the bus: the library's own timeout
            node.sdo.abort(0x05040001)  # another abort: still an error
        finally:
            network.disconnect()
    got = [json.loads(line)["message"] for line in log_file.read_text().splitlines()]
    timeouts = [m for m in got if m.endswith("0x05040000")]
    assert len(timeouts) == (1 if shown else 0), got
    assert "Transfer aborted by client with code 0x05040001" in got
