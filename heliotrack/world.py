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

With ``[hil.faults]`` the world also carries the fault hooks (:class:`WorldFaults`): a
:class:`~hil.wire_faults.WireFaults` per Modbus link (RTU: in the pty's serial handler;
TCP: in a :class:`~hil.tcp_proxy.FaultProxy` the controller connects through), a
:class:`~hil.canopen.faulty_bus.CanFaults` under each CAN emulator, and every drive in a
place that can be switched off and restarted with fresh firmware (:meth:`World.kill`,
:meth:`World.restart`).  :mod:`heliotrack.faults` switches them on the simulated clock.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field, replace

import can

from controller.clock import Clock
from controller.config import Config, TrackerConfig
from controller.drives.links import CanopenLink, LinkConfig, ModbusRtuLink, ModbusTcpLink
from controller.errors import ConfigError
from hil.anemometer import Anemometer
from hil.canopen import CanopenDriveEmulator, CanopenNetworkEmulator
from hil.canopen.faulty_bus import CanFaults, FaultyBus
from hil.drive import DriveFirmware
from hil.modbus_device import DeviceSlot, RegisterDevice
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink
from hil.pyranometer import Pyranometer
from hil.serial_urls.protocol_ptyfd import WIRE_FAULTS
from hil.tcp_proxy import FaultProxy
from hil.wind import WindScript
from hil.wire_faults import WireFaults

from .scenario import HilConfig, axis_params

#: Power-up watchdog timeout of a drive's firmware before the controller configures it, s.
FACTORY_HEARTBEAT_TIMEOUT_S = 10.0

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
    #: The fault hooks (always there; idle without ``[hil.faults]``).
    faults: WorldFaults = field(default_factory=lambda: WorldFaults())
    #: Firmwares replaced by a restart (their audit counts still count).
    retired: list[DriveFirmware] = field(default_factory=list)

    def all_firmwares(self) -> list[DriveFirmware]:
        """Every firmware that ran in this world, current and replaced."""
        return [*self.firmwares.values(), *self.retired]

    def kill(self, tracker: str) -> None:
        """The drive's emulator goes away: it answers nothing and its motors stop."""
        self.faults.drives[tracker].kill(self.firmwares[tracker])

    def restart(self, tracker: str) -> DriveFirmware:
        """The drive's emulator comes back with fresh firmware at its power-up state (where
        the panel is, in AUTO, factory watchdog, not configured by the controller)."""
        fw = self.faults.drives[tracker].restart(self.firmwares[tracker])
        self.retired.append(self.firmwares[tracker])
        self.firmwares[tracker] = fw
        return fw


@dataclass
class DriveHandle:
    """Where one drive lives in the world, for killing and restarting its emulator."""

    tracker: TrackerConfig
    device_id: int
    make: Callable[[list[float], float], DriveFirmware]
    slot: DeviceSlot | None = None  # Modbus
    proxy: FaultProxy | None = None  # Modbus TCP
    canopen: CanopenNetworkEmulator | None = None
    node: CanopenDriveEmulator | None = None

    def kill(self, fw: DriveFirmware) -> None:
        for ax in fw.axes:
            ax.enabled = False  # no power: the motors stop where they are
        if self.slot is not None:
            self.slot.powered = False
        if self.proxy is not None:
            self.proxy.set_down(self.device_id, True)
        if self.canopen is not None and self.node is not None:
            self.canopen.remove_drive(self.node)
            self.node = None

    def restart(self, old: DriveFirmware) -> DriveFirmware:
        fw = self.make(old.true_angles(), FACTORY_HEARTBEAT_TIMEOUT_S)
        if self.slot is not None:
            self.slot.device = fw
            self.slot.powered = True
        if self.proxy is not None:
            self.proxy.set_down(self.device_id, False)
        if self.canopen is not None:
            if self.node is not None:
                self.canopen.remove_drive(self.node)
            self.node = self.canopen.add_drive(fw, self.device_id)
        return fw


@dataclass
class WorldFaults:
    """The world's fault hooks, by link name and tracker name."""

    wire: dict[str, WireFaults] = field(default_factory=dict)
    can: dict[str, CanFaults] = field(default_factory=dict)
    proxies: dict[str, FaultProxy] = field(default_factory=dict)
    drives: dict[str, DriveHandle] = field(default_factory=dict)


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
    spec = hil.faults
    for i, link in enumerate(config.links):
        devices: dict[int, RegisterDevice] = {}
        drives: dict[int, DriveFirmware] = {}
        for tr in config.trackers:
            if tr.link != link.name:
                continue
            make = _firmware_factory(config, hil, clock, tr)
            # the firmware counts its own time: a step of the controller's wall clock must
            # not fire or delay its watchdog
            fw = make(None, config.control.heartbeat_timeout_s)
            world.firmwares[tr.name] = drives[tr.device_id] = fw
            slot = DeviceSlot(fw)
            devices[tr.device_id] = slot
            world.faults.drives[tr.name] = DriveHandle(
                tr, tr.device_id, make, slot=None if isinstance(link, CanopenLink) else slot
            )
        pyr = config.pyranometer
        if pyr is not None and pyr.link == link.name and ghi_at is not None:
            world.pyranometer = Pyranometer(ghi_at, clock.monotonic, seed=hil.seed)
            devices[pyr.device_id] = world.pyranometer
        if config.wind is not None and config.wind.link == link.name and wind is not None:
            world.anemometer = Anemometer(wind, clock.monotonic)
            devices[config.wind.device_id] = world.anemometer
        if not devices:
            continue
        seed = spec.seed * 1000 + i
        if isinstance(link, (ModbusRtuLink, ModbusTcpLink)) and spec.enabled:
            timeout = link.timeout_s
            world.faults.wire[link.name] = WireFaults(
                spec.per_transaction.wire_rates(),
                seed,
                late_s=(1.2 * timeout, 2.0 * timeout),
                split_gap_s=(0.002, min(0.05, 0.3 * timeout)),
                tcp=isinstance(link, ModbusTcpLink),
            )
        wire = world.faults.wire.get(link.name)
        if isinstance(link, ModbusRtuLink):
            world.links[link.name] = _serve_rtu(link, devices, stack, wire)
        elif isinstance(link, ModbusTcpLink):
            world.links[link.name], proxy = _serve_tcp(link, devices, stack, wire, spec.enabled)
            if proxy is not None:
                world.faults.proxies[link.name] = proxy
                for tr in config.trackers:
                    if tr.link == link.name:
                        world.faults.drives[tr.name].proxy = proxy
        elif isinstance(link, CanopenLink):
            can_faults = CanFaults(spec.per_transaction.can_frame_lost, seed) if spec.enabled else None
            world.links[link.name], emulator, nodes = _serve_canopen(link, drives, stack, can_faults)
            if can_faults is not None:
                world.faults.can[link.name] = can_faults
            for tr in config.trackers:
                if tr.link == link.name:
                    handle = world.faults.drives[tr.name]
                    handle.canopen, handle.node = emulator, nodes[tr.device_id]
        else:
            raise ConfigError(
                config.file,
                f"links[{i}].kind",
                f"a link kind the simulator emulates ({', '.join(EMULATED_KINDS)})",
                link.kind,
            )
    return world


def _firmware_factory(
    config: Config, hil: HilConfig, clock: Clock, tr: TrackerConfig
) -> Callable[[list[float] | None, float], DriveFirmware]:
    """A function making the tracker's drive firmware: at its stow angles (or at the given
    angles: a restart where the panel is), with the given watchdog timeout."""

    def make(angles: list[float] | None, heartbeat_timeout: float) -> DriveFirmware:
        axes = [axis_params(hil, soft, stow) for soft, stow in zip(tr.soft_limits, tr.stow_angles)]
        if angles is not None:
            axes = [replace(a, initial_angle=x) for a, x in zip(axes, angles)]
        fw = DriveFirmware(
            axes, clock.monotonic, heartbeat_timeout=heartbeat_timeout, audit_limits=tr.soft_limits
        )
        fw.mount_offsets = hil.mount_offset(tr.name, len(axes))
        return fw

    return make


def _serve_rtu(
    link: ModbusRtuLink, devices: dict[int, RegisterDevice], stack: ExitStack, wire: WireFaults | None
) -> ModbusRtuLink:
    """The line on a pty, served with the link's own line settings.

    The controller opens the pty's slave path, as it would ``/dev/ttyUSB0``; with parity,
    which Linux refuses on a pty, it opens the slave end by ``ptyfd://`` instead (pyserial
    takes the link's settings, the pty applies what it can).  Wire faults act on every
    frame the emulator writes to the pty.
    """
    pty = stack.enter_context(PtyLink.open())
    if wire is not None:
        WIRE_FAULTS[pty.master_fd] = wire
        stack.callback(WIRE_FAULTS.pop, pty.master_fd, None)
    stack.enter_context(
        ModbusServerThread(
            devices, serial_url=pty.url, baudrate=link.baudrate, parity=link.parity, stopbits=link.stopbits
        )
    )
    return replace(link, port=pty.path if link.parity == "N" else pty.slave_url)


def _serve_tcp(
    link: ModbusTcpLink,
    devices: dict[int, RegisterDevice],
    stack: ExitStack,
    wire: WireFaults | None,
    proxied: bool,
) -> tuple[ModbusTcpLink, FaultProxy | None]:
    """A gateway on 127.0.0.1, on a free port; with faults, behind a fault proxy (the
    controller connects to the proxy)."""
    srv = stack.enter_context(ModbusServerThread(devices, tcp=("127.0.0.1", 0)))
    assert srv.tcp_port is not None
    if not proxied:
        return replace(link, host="127.0.0.1", tcp_port=srv.tcp_port), None
    proxy = stack.enter_context(FaultProxy(srv.tcp_port, wire))
    return replace(link, host="127.0.0.1", tcp_port=proxy.port), proxy


def _serve_canopen(
    link: CanopenLink, drives: dict[int, DriveFirmware], stack: ExitStack, faults: CanFaults | None
) -> tuple[CanopenLink, CanopenNetworkEmulator, dict[int, CanopenDriveEmulator]]:
    """The drives as CiA 402 nodes on a virtual bus of this run's own (with faults: under a
    bus that loses frames as told)."""
    channel = f"heliotrack-sim-{os.getpid()}-{link.name}-{uuid.uuid4().hex[:8]}"
    if faults is None:
        emulator = CanopenNetworkEmulator(channel, interface="virtual")
    else:
        bus = FaultyBus(can.Bus(interface="virtual", channel=channel), faults)
        emulator = CanopenNetworkEmulator(channel, bus=bus)
    stack.callback(emulator.stop)
    nodes = {node_id: emulator.add_drive(fw, node_id) for node_id, fw in drives.items()}
    emulator.start()
    return replace(link, interface="virtual", channel=channel), emulator, nodes
