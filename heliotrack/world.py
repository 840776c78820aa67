"""The emulated world of a scenario: one drive firmware per tracker (and the pyranometer),
served on every configured link the way real hardware would be.

- ``modbus-rtu``: a pymodbus server on a pseudo-terminal, with the link's line settings;
  the controller opens the pty's slave end like a USB-RS485 adapter.
- ``modbus-tcp``: one pymodbus server on 127.0.0.1 (a gateway: every device of the link
  behind one endpoint, told apart by unit id).
- ``canopen``: every drive as CiA 402 nodes (``hil.canopen``) on a python-can ``virtual``
  bus whose channel name is unique to the run, so parallel runs never share a bus.

The scenario's addresses (``port``, ``host``, ``channel``) are replaced by the emulator's:
:attr:`World.links` is what the controller connects to.  Everything is registered on the
caller's :class:`~contextlib.ExitStack`, which shuts it down.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field, replace

from controller.clock import Clock
from controller.config import Config
from controller.drives.links import CanopenLink, LinkConfig, ModbusRtuLink, ModbusTcpLink
from controller.errors import ConfigError
from hil.anemometer import Anemometer
from hil.canopen import CanopenNetworkEmulator
from hil.drive import DriveFirmware
from hil.modbus_device import RegisterDevice
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink
from hil.pyranometer import Pyranometer
from hil.wind import WindScript

from .scenario import HilConfig, axis_params

#: Link settings classes the simulator can emulate.
EMULATED_KINDS = ("canopen", "modbus-rtu", "modbus-tcp")


@dataclass
class World:
    """What :func:`build_world` made."""

    #: The emulated drive of each tracker, by tracker name (the truth is read from it).
    firmwares: dict[str, DriveFirmware] = field(default_factory=dict)
    #: Each link as the controller reaches the emulators, by link name.
    links: dict[str, LinkConfig] = field(default_factory=dict)
    #: The emulated pyranometer, when one is configured.
    pyranometer: Pyranometer | None = None
    #: The emulated anemometer, when ``[wind]`` is configured.
    anemometer: Anemometer | None = None


def build_world(
    config: Config,
    hil: HilConfig,
    clock: Clock,
    stack: ExitStack,
    ghi_at: Callable[[float], float] | None = None,
    wind: WindScript | None = None,
) -> World:
    """Emulate every device of ``config`` on its link.

    Parameters
    ----------
    config : Config
        The plant.
    hil : HilConfig
        The world's settings (drive mechanics, seed).
    clock : Clock
        The physics clock (simulated or wall); bus timing stays on the wall clock.
    stack : ExitStack
        Servers, ptys and buses are entered on it.
    ghi_at : callable, optional
        POSIX time -> true GHI, W/m2: the pyranometer's sky (no pyranometer without it).
    wind : WindScript, optional
        The anemometer's wind (no anemometer without it).

    Raises
    ------
    ConfigError
        A link kind the simulator does not emulate (a plug-in backend).
    """
    world = World()
    for i, link in enumerate(config.links):
        devices: dict[int, RegisterDevice] = {}
        drives: dict[int, DriveFirmware] = {}
        for tr in config.trackers:
            if tr.link != link.name:
                continue
            axes = [axis_params(hil, soft, stow) for soft, stow in zip(tr.soft_limits, tr.stow_angles)]
            # the firmware counts its own time: a step of the controller's wall clock must
            # not fire or delay its watchdog
            fw = DriveFirmware(axes, clock.monotonic, heartbeat_timeout=config.control.heartbeat_timeout_s)
            world.firmwares[tr.name] = drives[tr.device_id] = devices[tr.device_id] = fw
        pyr = config.pyranometer
        if pyr is not None and pyr.link == link.name and ghi_at is not None:
            world.pyranometer = Pyranometer(ghi_at, clock.monotonic, seed=hil.seed)
            devices[pyr.device_id] = world.pyranometer
        if config.wind is not None and config.wind.link == link.name and wind is not None:
            world.anemometer = Anemometer(wind, clock.monotonic)
            devices[config.wind.device_id] = world.anemometer
        if not devices:
            continue
        if isinstance(link, ModbusRtuLink):
            world.links[link.name] = _serve_rtu(link, devices, stack)
        elif isinstance(link, ModbusTcpLink):
            world.links[link.name] = _serve_tcp(link, devices, stack)
        elif isinstance(link, CanopenLink):
            world.links[link.name] = _serve_canopen(link, drives, stack)
        else:
            raise ConfigError(
                config.file,
                f"links[{i}].kind",
                f"a link kind the simulator emulates ({', '.join(EMULATED_KINDS)})",
                link.kind,
            )
    return world


def _serve_rtu(link: ModbusRtuLink, devices: dict[int, RegisterDevice], stack: ExitStack) -> ModbusRtuLink:
    """The line on a pty, served with the link's own line settings.

    The controller opens the pty's slave path, as it would ``/dev/ttyUSB0``; with parity,
    which Linux refuses on a pty, it opens the slave end by ``ptyfd://`` instead (pyserial
    takes the link's settings, the pty applies what it can).
    """
    pty = stack.enter_context(PtyLink.open())
    stack.enter_context(
        ModbusServerThread(
            devices, serial_url=pty.url, baudrate=link.baudrate, parity=link.parity, stopbits=link.stopbits
        )
    )
    return replace(link, port=pty.path if link.parity == "N" else pty.slave_url)


def _serve_tcp(link: ModbusTcpLink, devices: dict[int, RegisterDevice], stack: ExitStack) -> ModbusTcpLink:
    """A gateway on 127.0.0.1, on a free port."""
    srv = stack.enter_context(ModbusServerThread(devices, tcp=("127.0.0.1", 0)))
    assert srv.tcp_port is not None
    return replace(link, host="127.0.0.1", tcp_port=srv.tcp_port)


def _serve_canopen(link: CanopenLink, drives: dict[int, DriveFirmware], stack: ExitStack) -> CanopenLink:
    """The drives as CiA 402 nodes on a virtual bus of this run's own."""
    channel = f"heliotrack-sim-{os.getpid()}-{link.name}-{uuid.uuid4().hex[:8]}"
    emulator = CanopenNetworkEmulator(channel, interface="virtual")
    stack.callback(emulator.stop)
    for node_id, fw in drives.items():
        emulator.add_drive(fw, node_id)
    emulator.start()
    return replace(link, interface="virtual", channel=channel)
