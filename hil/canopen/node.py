"""One axis of an emulated drive as a CANopen CiA 402 slave (canopen ``LocalNode``).

The node owns no physics: every value it reports and every write it accepts goes through
the register words of :class:`hil.drive.firmware.DriveFirmware` (the same firmware the
Modbus emulator serves), converted with the ``firmware_protocol`` codecs.  It adds what
CANopen has and Modbus lacks: the CiA 402 power state machine, the profile-position
set-point handshake, PDOs, EMCY and the heartbeat protocol.

The canopen library's ``LocalNode`` neither copies received RPDO data into its data store
nor TPDO data from it, so the node does both itself (RPDO callbacks, and :meth:`service`
filling the TPDOs from live values).
"""

from __future__ import annotations

import io
import logging
import math
import time
from collections.abc import Callable

import canopen
from canopen.objectdictionary import eds as eds_format
from canopen.sdo import SdoAbortedError

from firmware_protocol import Command, Fault, Mode, ProtocolError, Status, encode, register
from firmware_protocol.canopen import (
    AXIS_INDEX_OBJECT,
    FAULT_ERROR_CODES,
    PROFILE_POSITION,
    Controlword,
    State402,
    Statusword,
    entry,
)
from firmware_protocol.codec import words_to_raw
from firmware_protocol.eds import eds
from firmware_protocol.registers import AXIS_BASE, AXIS_REGISTERS, AXIS_STRIDE
from hil.drive.firmware import FirmwareReject

from .cia402 import Cia402StateMachine
from .drive_bus import DriveBus
from .pdo_rules import check_pdo_write, stored_in

log = logging.getLogger(__name__)

ABORT_VALUE_RANGE = 0x06090030
ABORT_READ_ONLY = 0x06010002
ABORT_NO_SUBINDEX = 0x06090011
ABORT_STATE = 0x08000022  # data cannot be transferred because of the device state
EMCY_PDO_LENGTH = 0x8210  # PDO not processed due to length error
_SNAPSHOT_WORDS = 8  # axis registers TARGET_ANGLE .. MODE (offsets 0-7)
_NOT_ERROR_CODE = 0xFF00  # generic manufacturer code for a fault without a mapping


def object_dictionary(node_id: int) -> canopen.ObjectDictionary:
    """The generated EDS parsed for ``node_id`` (a fresh copy each call)."""
    return eds_format.import_eds(io.StringIO(eds()), node_id)


class AxisNode:
    """Axis ``axis`` of a drive as CANopen node ``node_id``.

    Parameters
    ----------
    drive : DriveBus
        Shared firmware and lock.
    axis : int
        Axis index inside the drive (0 or 1).
    node_id : int
        CANopen node id (1..126).
    wall : callable
        Monotonic seconds for bus timing (event timers, inhibit times).  Bus timing stays
        on the wall clock even when the physics runs on a simulated one, because masters
        time out on the wall clock.
    """

    def __init__(self, drive: DriveBus, axis: int, node_id: int, wall: Callable[[], float] = time.monotonic):
        self.drive = drive
        self.fw = drive.fw
        self.axis = axis
        self.node_id = node_id
        self.node = canopen.LocalNode(node_id, object_dictionary(node_id))
        self.sm = Cia402StateMachine()
        self.wall = wall
        self.op_mode = PROFILE_POSITION
        self.target_raw = 0
        self.ack = False
        self._listening: int | None = None  # producer whose heartbeat COB-ID we subscribe
        self._fault_seen = Fault.NONE
        self._pdo_dirty = False
        self._halted_target: float | None = None  # the target a halt (bit 8) put off
        self._sync_count = 0
        self._last_tx: dict[int, tuple[list[int], float]] = {}  # TPDO no -> (values, t)
        self.network: canopen.Network | None = None
        drive.nodes.append(self)

    @property
    def id(self) -> int:
        return self.node_id

    @property
    def heartbeat_producer(self) -> int:
        return self.drive.producer

    # -- wiring ------------------------------------------------------------------------
    def attach(self, network: canopen.Network) -> None:
        """Join ``network``: SDO server, NMT, PDOs, SYNC and heartbeat consumer."""
        self.network = network
        serve = self.node.sdo.on_request

        def sdo_unless_stopped(can_id: int, data: bytearray, timestamp: float) -> None:
            # CiA 301: a STOPPED node answers NMT and sends its heartbeat, nothing else
            if self.node.nmt.state != "STOPPED":
                serve(can_id, data, timestamp)

        self.node.sdo.on_request = sdo_unless_stopped  # type: ignore[method-assign]
        network.add_node(self.node)
        self.node.add_read_callback(self._on_sdo_read)
        self.node.add_write_callback(self._on_sdo_write)
        self._load_pdos(from_od=True)
        for rpdo in self.node.rpdo.values():
            rpdo.add_callback(self._on_rpdo)
        network.subscribe(0x80, self._on_sync)
        self.listen_to(self.drive.producer)
        self._boot()

    def detach(self) -> None:
        if self.network is None:
            return
        self.node.nmt.stop_heartbeat()
        self.network.unsubscribe(0x80, self._on_sync)
        if self._listening is not None:
            self.network.unsubscribe(0x700 + self._listening, self._on_master_heartbeat)
            self._listening = None
        for pdo in list(self.node.rpdo.values()) + list(self.node.tpdo.values()):
            if pdo.cob_id:
                self.network.unsubscribe(pdo.cob_id, pdo.on_message)
        self.node.remove_network()
        self.network.nodes.pop(self.id, None)
        self.network = None

    def listen_to(self, producer: int) -> None:
        """Feed the drive's watchdog from the heartbeats of node ``producer``."""
        if self.network is None or producer == self._listening:
            return
        if self._listening is not None:
            self.network.unsubscribe(0x700 + self._listening, self._on_master_heartbeat)
        self.network.subscribe(0x700 + producer, self._on_master_heartbeat)
        self._listening = producer

    def _load_pdos(self, from_od: bool) -> None:
        for pdos in (self.node.rpdo, self.node.tpdo):
            for pdo in pdos.values():
                pdo.read(from_od=from_od)

    def _boot(self) -> None:
        """Power-up / NMT reset: boot-up message, PRE-OPERATIONAL, 402 state machine reset."""
        with self.drive.lock:
            self.sm.reset()
            self.ack = False
            self.node.nmt.send_command(0x81)  # INITIALISING: sends the boot-up message
            self.node.nmt.send_command(0x80)  # PRE-OPERATIONAL: starts the heartbeat
            self.sm.boot()
            self._last_tx.clear()

    # -- firmware access -----------------------------------------------------------------
    def _snapshot(self) -> dict[str, int]:
        """Raw values of the axis registers TARGET_ANGLE .. MODE, read in one access."""
        base = AXIS_BASE + self.axis * AXIS_STRIDE
        words = self.fw.read(base, _SNAPSHOT_WORDS)
        out = {}
        for reg in AXIS_REGISTERS:
            if reg.offset + reg.words <= _SNAPSHOT_WORDS:
                out[reg.name] = words_to_raw(reg, words[reg.offset : reg.offset + reg.words])
        return out

    def _reg_raw(self, name: str) -> int:
        reg = register(name)
        addr = reg.address(self.axis if reg.per_axis else None)
        return words_to_raw(reg, self.fw.read(addr, reg.words))

    def _reg_write_raw(self, name: str, raw: int) -> None:
        """Write a register from its raw wire value (raises ProtocolError/FirmwareReject)."""
        reg = register(name)
        words = encode(reg, raw * reg.scale) if reg.scale != 1 else encode(reg, raw)
        self.fw.write(reg.address(self.axis if reg.per_axis else None), words)

    def _halt(self) -> None:
        """Stop where the axis is (leaving OPERATION ENABLED, quick stop, fault, halt bit)."""
        self.fw.halt(self.axis, self._reg_raw("ACTUAL_ANGLE") * register("ACTUAL_ANGLE").scale)

    # -- values --------------------------------------------------------------------------
    def statusword(self, snap: dict[str, int]) -> int:
        st = Status(snap["STATUS"])
        sw = self.sm.state_bits | Statusword.REMOTE
        if self.sm.state in (
            State402.READY_TO_SWITCH_ON,
            State402.SWITCHED_ON,
            State402.OPERATION_ENABLED,
            State402.QUICK_STOP_ACTIVE,
        ):
            sw |= Statusword.VOLTAGE_ENABLED
        if st & Status.AT_TARGET:
            sw |= Statusword.TARGET_REACHED
        if st & (Status.TARGET_CLAMPED | Status.LIMIT_POS | Status.LIMIT_NEG):
            sw |= Statusword.INTERNAL_LIMIT
        if st & Status.STALLED:
            sw |= Statusword.FOLLOWING_ERROR
        if st & Status.COMM_LOST or snap["MODE"] == Mode.STOW:
            sw |= Statusword.WARNING
        if self.ack:
            sw |= Statusword.SET_POINT_ACK
        return int(sw)

    def object_raw(self, index: int, subindex: int, snap: dict[str, int] | None = None) -> int | None:
        """Live raw value of an object, or None when the data store holds it."""
        snap = snap if snap is not None else self._snapshot()
        if index == 0x6041:
            return self.statusword(snap)
        if index == 0x6061:
            return self.op_mode
        if index == 0x6060:
            return self.op_mode
        if index == 0x6040:
            return self.sm.controlword
        if index == 0x607A:
            return self.target_raw
        if index == 0x603F:
            try:
                return FAULT_ERROR_CODES[Fault(snap["FAULT_CODE"])]
            except (ValueError, KeyError):
                return _NOT_ERROR_CODE
        if index == 0x1001:
            return 0x01 if snap["FAULT_CODE"] else 0x00
        if index == 0x1016 and subindex == 1:
            ms = self._reg_raw("HEARTBEAT_TIMEOUT") * 100
            return (self.heartbeat_producer << 16) | min(ms, 0xFFFF)
        if index == AXIS_INDEX_OBJECT:
            return self.axis
        try:
            e = entry(index, subindex)
        except KeyError:
            return None
        if not e.register or e.register == "HEARTBEAT_TIMEOUT" and index == 0x1016:
            return None
        return snap[e.register] if e.register in snap else self._reg_raw(e.register)

    # -- SDO ----------------------------------------------------------------------------
    def _on_sdo_read(self, index: int, subindex: int, od, **_) -> int | None:
        _subindex_exists(index, subindex)
        with self.drive.lock:
            return self.object_raw(index, subindex)

    def _on_sdo_write(self, index: int, subindex: int, od, data: bytes, **_) -> None:
        _subindex_exists(index, subindex)
        if od.data_type not in canopen.objectdictionary.NUMBER_TYPES:
            return
        value = od.decode_raw(data)
        with self.drive.lock:
            self.write_object(index, subindex, value)
            # The data store is written after this callback: PDO parameters are
            # re-read on the next service() call, not now.
            self._service_locked(self.wall(), reload_pdos=False)

    def write_object(self, index: int, subindex: int, value: int) -> None:
        """Apply a write from SDO or RPDO; raise SdoAbortedError to refuse it."""
        if index == 0x6040:
            self._controlword(value)
        elif index == 0x607A:
            self.target_raw = value
        elif index == 0x6060:
            if value not in (0, PROFILE_POSITION):
                raise SdoAbortedError(ABORT_VALUE_RANGE)
            self.op_mode = value
        elif index == 0x1016 and subindex == 1:
            self._set_consumer(value)
        elif 0x1400 <= index < 0x1C00:
            check_pdo_write(self.node.object_dictionary, index, subindex, value, stored_in(self.node))
            self._pdo_dirty = True  # stored after this callback; re-read in service()
        else:
            try:
                e = entry(index, subindex)
            except KeyError:
                return
            if not e.register:
                return
            if e.access != "rw":
                raise SdoAbortedError(ABORT_READ_ONLY)
            self._firmware_write(index, subindex, e.register, value)

    def _firmware_write(self, index: int, subindex: int, name: str, value: int) -> None:
        """Write register ``name`` through the firmware's validation (the Modbus interlocks).
        Refused: abort 0x08000022 for a valid value the drive's state forbids (a MODE, the
        watchdog off outside MAINTENANCE), else 0x06090030 (range, limits, stow angle)."""
        try:
            self._reg_write_raw(name, value)
        except (ProtocolError, FirmwareReject) as exc:
            log.info("node %d: write 0x%04X:%02X = %d refused: %s", self.id, index, subindex, value, exc)
            state = isinstance(exc, FirmwareReject) and (
                name == "HEARTBEAT_TIMEOUT" or name == "MODE" and any(value == m for m in Mode)
            )
            raise SdoAbortedError(ABORT_STATE if state else ABORT_VALUE_RANGE) from None

    def _set_consumer(self, value: int) -> None:
        """0x1016:1 = ``(producer << 16) | ms`` for the whole drive.  CiA 301: bits 24-31
        reserved; a node id or time of 0 is "not monitored" (the watchdog off: MAINTENANCE
        only).  A drive never watches its own nodes (they would keep it alive alone)."""
        producer, ms = (value >> 16) & 0xFF, value & 0xFFFF
        if value >> 24 or producer > 0x7F or producer in self.drive.node_ids:
            log.info("node %d: consumer heartbeat 0x%08X refused", self.id, value)
            raise SdoAbortedError(ABORT_VALUE_RANGE)
        # The firmware watchdog counts in 0.1 s; round up so a short timeout never
        # becomes 0 (which would disable the watchdog).
        tenths = math.ceil(ms / 100) if producer else 0
        self._firmware_write(0x1016, 1, "HEARTBEAT_TIMEOUT", tenths)
        if tenths:
            self.drive.set_producer(producer)

    # -- CiA 402 ------------------------------------------------------------------------
    def _controlword(self, cw: int) -> None:
        prev = self.sm.controlword
        old, new = self.sm.on_controlword(cw)
        if old == State402.OPERATION_ENABLED and new != State402.OPERATION_ENABLED:
            self._halt()
        if self.sm.fault_reset_edge:
            self._fault_reset()
        if not cw & Controlword.NEW_SET_POINT:
            self.ack = False
        if new != State402.OPERATION_ENABLED:
            self._halted_target = None  # leaving the state ends the motion: nothing to resume
            return
        if cw & Controlword.HALT:
            if not prev & Controlword.HALT:
                self._halted_target = self._reg_raw("TARGET_ANGLE") * register("TARGET_ANGLE").scale
                self._halt()
            return
        if prev & Controlword.HALT and self._halted_target is not None:
            # CiA 402 profile position: clearing the halt bit resumes the motion to the target
            self.fw.halt(self.axis, self._halted_target)
            self._halted_target = None
        if cw & Controlword.NEW_SET_POINT and not prev & Controlword.NEW_SET_POINT:
            self._new_set_point(cw)

    def _new_set_point(self, cw: int) -> None:
        if self.op_mode != PROFILE_POSITION:
            return  # no acknowledge: the master sees the set-point was not taken
        raw = self.target_raw
        if cw & Controlword.RELATIVE:
            raw += self._reg_raw("TARGET_ANGLE")
        try:
            self._reg_write_raw("TARGET_ANGLE", raw)
        except (ProtocolError, FirmwareReject) as exc:
            log.info("node %d: set-point %d refused: %s", self.id, raw, exc)
            return
        self.ack = True

    def _fault_reset(self) -> None:
        """A fault reset edge: CLEAR_FAULT is the drive's command, so it clears every axis
        whose cause is gone, and each such axis's node leaves FAULT with it (a reset on
        one node had left the other axis's node in 402 FAULT with no fault code)."""
        self.fw.write(register("COMMAND").address(), encode("COMMAND", int(Command.CLEAR_FAULT)))
        self.sm.fault_reset_edge = False
        for node in self.drive.nodes:
            node._leave_fault_if_cleared()

    def _leave_fault_if_cleared(self) -> None:
        if self._reg_raw("FAULT_CODE") != Fault.NONE or self.sm.state != State402.FAULT:
            return
        self.sm.fault_cleared()
        self._fault_seen = Fault.NONE
        if self.network is not None:
            self.node.emcy.reset()

    def _check_fault(self, snap: dict[str, int]) -> None:
        code = snap["FAULT_CODE"]
        if code == Fault.NONE:
            return
        if self.sm.on_fault():
            self._halt()
            self.ack = False
            try:
                fault = Fault(code)
            except ValueError:
                fault = None
            err = FAULT_ERROR_CODES.get(fault, _NOT_ERROR_CODE) if fault else _NOT_ERROR_CODE
            self._fault_seen = fault or Fault.NONE
            if self.network is not None:
                self.node.emcy.send(err, 0x01)

    # -- bus events ------------------------------------------------------------------
    def _on_rpdo(self, pdo) -> None:
        with self.drive.lock:
            if self.node.nmt.state != "OPERATIONAL":
                return
            if len(pdo.data) * 8 < pdo.length:
                # CiA 301: a too-short PDO is not processed; report it.
                self.node.emcy.send(EMCY_PDO_LENGTH)
                return
            values = [(var.index, var.subindex, var.raw) for var in pdo]
            # Objects first, the controlword last: a new-set-point edge latches the
            # target position carried by the same PDO.
            values.sort(key=lambda v: v[0] == 0x6040)
            for index, subindex, value in values:
                try:
                    self.write_object(index, subindex, value)
                except SdoAbortedError as exc:
                    log.info("node %d: RPDO value 0x%04X = %d ignored (%s)", self.id, index, value, exc)
            self._service_locked(self.wall())

    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self.drive.lock:
            if self.node.nmt.state != "OPERATIONAL":
                return
            self._sync_count += 1
            snap = self._snapshot()
            for no, pdo in self.node.tpdo.items():
                tt = pdo.trans_type
                if not pdo.enabled or tt is None or tt > 240:
                    continue
                if tt == 0 and not self._changed(no, pdo, snap) or tt and self._sync_count % tt:
                    continue
                self._send(no, pdo, snap, self.wall())

    def resend_tpdos(self) -> None:
        """Every TPDO goes out again at the next service, as after boot (on an NMT start)."""
        with self.drive.lock:
            self._last_tx.clear()

    def _on_master_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self.drive.lock:
            self.drive.beat()

    # -- periodic work ------------------------------------------------------------------
    def service(self) -> None:
        """Housekeeping: NMT resets, faults, event-driven and timed TPDOs."""
        with self.drive.lock:
            self._service_locked(self.wall())

    def _service_locked(self, t: float, reload_pdos: bool = True) -> None:
        if self.node.nmt.state == "INITIALISING":  # NMT reset node / communication
            self.node.data_store.clear()
            self._load_pdos(from_od=True)
            self._boot()
        if self._pdo_dirty and reload_pdos:
            self._pdo_dirty = False
            self._load_pdos(from_od=False)
        self.sm.boot()
        snap = self._snapshot()
        self._check_fault(snap)
        if self.node.nmt.state != "OPERATIONAL":
            return
        for no, pdo in self.node.tpdo.items():
            if not pdo.enabled or pdo.trans_type is None or pdo.trans_type < 254:
                continue
            last = self._last_tx.get(no)
            inhibit = (pdo.inhibit_time or 0) * 1e-4
            if last is not None and t - last[1] < inhibit:
                continue
            timer = (pdo.event_timer or 0) / 1000
            due = last is None or (timer and t - last[1] >= timer)
            if due or self._changed(no, pdo, snap):
                self._send(no, pdo, snap, t)

    def _values(self, pdo, snap) -> list[int]:
        return [self.object_raw(v.index, v.subindex, snap) or 0 for v in pdo]

    def _changed(self, no: int, pdo, snap) -> bool:
        last = self._last_tx.get(no)
        return last is None or last[0] != self._values(pdo, snap)

    def _send(self, no: int, pdo, snap, t: float) -> None:
        values = self._values(pdo, snap)
        try:
            for var, value in zip(pdo, values):
                var.raw = value
            pdo.transmit()
        except Exception as exc:  # noqa: BLE001 - a value that does not fit its mapping, a closed bus
            log.warning("node %d: TPDO%d not sent: %s", self.id, no, exc)
            return
        self._last_tx[no] = (values, t)


def _subindex_exists(index: int, subindex: int) -> None:
    """Abort 0x06090011 for a sub-index the object does not have: canopen's dictionary makes
    up any sub-index of an array and takes any of a variable, which a real node refuses."""
    try:
        entry(index, subindex)
    except KeyError:
        raise SdoAbortedError(ABORT_NO_SUBINDEX) from None


__all__ = ["AxisNode", "DriveBus", "object_dictionary"]
