"""The drive-link registry: built-in kinds imported on first use, third-party backends
through a real entry point, clear errors for unknown or broken kinds."""

import asyncio
import subprocess
import sys
import textwrap

import pytest

from controller.config import parse_config
from controller.drives import registry
from controller.drives.registry import BackendLoadError, known_kinds, open_drive
from controller.errors import ConfigError
from tests.conftest import REPO

PLUGIN = '''
"""A third-party drive backend: a drive that answers from memory."""

from dataclasses import dataclass
from typing import Literal

from controller.drives.base import AxisState, DriveLink, DriveState, LinkStats
from controller.drives.links import LinkConfig
from controller.schema import setting
from firmware_protocol import Fault, Mode, Status


@dataclass(frozen=True, kw_only=True)
class LoopbackLink(LinkConfig):
    """A link to drives that live in memory."""

    kind: Literal["loopback"] = setting("loopback", doc="Loopback.")
    gain: float = setting(1.0, doc="Actual angle per target angle.", ge=0, le=2)


class LoopbackDrive(DriveLink):
    config_type = LoopbackLink

    def __init__(self, gain, device_id):
        self.gain, self.device_id, self.stats, self.targets = gain, device_id, LinkStats(), []

    @classmethod
    def from_config(cls, link, device_id):
        return cls(link.gain, device_id)

    async def connect(self):
        self.axis_count = 1

    async def close(self):
        pass

    async def read_state(self):
        t = self.targets[0] if self.targets else 0.0
        axis = AxisState(self.gain * t, t, 0.0, Status.AT_TARGET, Fault.NONE, Mode.AUTO)
        return DriveState(1, (axis,))

    async def write_targets(self, angles_deg):
        self.targets = list(angles_deg)

    async def heartbeat(self):
        pass

    async def command(self, cmd):
        pass

    async def configure(self, **kw):
        pass
'''


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """A distribution installed on sys.path, declaring one backend in the group."""
    (tmp_path / "ht_loopback.py").write_text(PLUGIN)
    dist = tmp_path / "ht_loopback-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: ht-loopback\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(
        textwrap.dedent("""\
        [heliotrack.drive_links]
        loopback = ht_loopback:LoopbackDrive
        broken = ht_missing_module:Drive
        modbus-rtu = ht_loopback:LoopbackDrive
        """)
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    registry.reload_plugins()
    yield
    monkeypatch.undo()
    sys.modules.pop("ht_loopback", None)
    registry.reload_plugins()


def plant(link: dict) -> dict:
    return {
        "site": {"latitude": 10, "longitude": 20},
        "links": [link],
        "trackers": [{"name": "row", "type": "single-axis", "link": link["name"], "device_id": 3}],
    }


def test_a_plug_in_backend_is_found_validated_and_built(plugin):
    assert known_kinds()["loopback"] == "ht_loopback:LoopbackDrive"
    assert known_kinds()["modbus-rtu"] == "controller.drives.modbus:ModbusRtuDrive"  # no override
    cfg = parse_config(plant({"name": "mem", "kind": "loopback", "gain": 0.5}))
    link = cfg.links[0]
    assert type(link).__name__ == "LoopbackLink" and link.gain == 0.5
    with pytest.raises(ConfigError, match=r"links\[0\].gain: expected a number in \[0, 2\], got 3"):
        parse_config(plant({"name": "mem", "kind": "loopback", "gain": 3}))
    with pytest.raises(ConfigError, match=r"links\[0\].port: expected one of the known keys"):
        parse_config(plant({"name": "mem", "kind": "loopback", "port": "/dev/ttyUSB0"}))

    drive = open_drive(link, cfg.trackers[0].device_id)
    assert type(drive).__name__ == "LoopbackDrive" and drive.device_id == 3

    async def exchange():
        await drive.connect()
        return await drive.exchange([20.0])

    assert asyncio.run(exchange()).axes[0].actual_deg == pytest.approx(10.0)


def test_an_unknown_kind_is_a_config_error_listing_the_known_kinds(plugin):
    with pytest.raises(ConfigError) as err:
        parse_config(plant({"name": "x", "kind": "profibus"}))
    msg = str(err.value)
    assert "links[0].kind" in msg and "'profibus'" in msg
    assert "canopen, loopback, modbus-rtu, modbus-tcp" in msg


def test_a_broken_plug_in_is_a_clear_error_only_where_it_is_used(plugin):
    cfg = parse_config(plant({"name": "mem", "kind": "loopback"}))  # other kinds load fine
    assert cfg.links[0].kind == "loopback"
    with pytest.raises(BackendLoadError, match="'broken'.*ht_missing_module:Drive.*ModuleNotFoundError"):
        parse_config(plant({"name": "x", "kind": "broken"}))


def test_without_the_plug_in_its_kind_is_unknown():
    assert "loopback" not in known_kinds()
    with pytest.raises(ConfigError, match="one of canopen, modbus-rtu, modbus-tcp"):
        parse_config(plant({"name": "mem", "kind": "loopback"}))


def test_importing_the_drives_package_imports_no_backend():
    code = (
        "import sys, controller.drives, controller.drives.registry\n"
        "loaded = sorted(m for m in sys.modules if m.split('.')[0] in ('pymodbus', 'canopen', 'can')"
        " or m.startswith(('controller.drives.modbus', 'controller.drives.canopen')))\n"
        "print(loaded)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    assert out.stdout.strip() == "[]"


def test_a_configuration_imports_only_the_backends_it_uses():
    code = (
        "import sys\nfrom controller.config import parse_config\n"
        "parse_config({'site': {'latitude': 1, 'longitude': 2}, 'links': [{'name': 'l', "
        "'kind': 'modbus-tcp', 'host': '127.0.0.1'}], 'trackers': [{'name': 'r', 'type': "
        "'single-axis', 'link': 'l', 'device_id': 1}]})\n"
        "print('canopen' in sys.modules, 'pymodbus' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    assert out.stdout.split() == ["False", "True"]
