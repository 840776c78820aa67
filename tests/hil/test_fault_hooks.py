"""The emulators' fault hooks: drive faults, audit counters, sensor faults, a device switched
off, camera frames."""

import math

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

from firmware_protocol import Command, Fault, encode, register
from hil.camera.faults import CAMERA_FAULTS, damage
from hil.drive import AxisParams, DriveFirmware
from hil.modbus_device import DeviceSlot
from hil.modbus_server import ModbusServerThread
from hil.pyranometer import NAN_WORD_INT16, Pyranometer


def one_axis(clock_t):
    p = AxisParams(soft_min=-50, soft_max=50, hard_min=-55, hard_max=55, stow_angle=0, initial_angle=0)
    return DriveFirmware([p], lambda: clock_t[0], heartbeat_timeout=0, audit_limits=[(-45.0, 45.0)])


def write_target(fw, angle):
    reg = register("TARGET_ANGLE")
    fw.write(reg.address(0), encode(reg, angle))


def command(fw, cmd):
    fw.write(register("COMMAND").address(), [int(cmd)])


def test_a_tripped_limit_switch_latches_until_released_and_cleared():
    t = [0.0]
    fw = one_axis(t)
    ax = fw.axes[0]
    ax.trip_limit()
    assert fw.fault(0) == Fault.HARD_LIMIT
    command(fw, Command.CLEAR_FAULT)
    assert fw.fault(0) == Fault.HARD_LIMIT  # still pressed
    ax.limit_stuck = False
    command(fw, Command.CLEAR_FAULT)
    assert fw.fault(0) == Fault.NONE


def test_an_encoder_glitch_moves_the_panel_while_it_lasts():
    t = [0.0]
    fw = one_axis(t)
    fw.axes[0].encoder_offset = 2.0  # the reading is 2 deg high: the loop drives 2 deg low
    t[0] = 10.0
    assert fw.true_angles()[0] == pytest.approx(-2.0, abs=0.05)
    fw.axes[0].encoder_offset = 0.0
    t[0] = 20.0
    assert fw.true_angles()[0] == pytest.approx(0.0, abs=0.05)


def test_the_firmware_counts_targets_outside_the_limits():
    t = [0.0]
    fw = one_axis(t)
    write_target(fw, 30.0)
    write_target(fw, 47.0)  # inside the soft limits, outside the tracker's travel
    write_target(fw, 70.0)  # outside both (clamped)
    assert fw.target_writes == 3 and fw.out_of_limit_writes == 2
    assert fw.last_target_written[0] == pytest.approx(70.0)
    # what a soak shows of them: the value, the limits it broke, the drive's own limits
    (_, k, v, broken, soft), (_, _, v2, _, _) = fw.out_of_limit_samples
    assert k == 0 and v == pytest.approx(47.0) and v2 == pytest.approx(70.0)
    assert broken[1] < 47.0 <= soft[1]


def test_pyranometer_faults_out_of_range_nan_and_frozen():
    t = [43200.0]
    pyr = Pyranometer(lambda _t: 500.0 + _t % 7, lambda: t[0], noise_w_m2=0)
    first = pyr.read(5, 1)[0]
    pyr.override = 2500.0
    assert pyr.read(5, 1) == [2500]
    pyr.override = math.nan
    assert pyr.read(5, 2) == [NAN_WORD_INT16, NAN_WORD_INT16]
    pyr.override = None
    pyr.frozen_at = t[0]
    frozen = pyr.read(0, 32)
    t[0] += 3.0
    assert pyr.read(0, 32) == frozen  # the words stop changing
    pyr.frozen_at = None
    assert pyr.read(5, 1)[0] != frozen[5] and first != 0


def test_a_switched_off_device_answers_nothing_and_comes_back_as_new():
    t = [0.0]
    slot = DeviceSlot(one_axis(t))
    with ModbusServerThread({4: slot}, tcp=("127.0.0.1", 0)) as srv:
        c = ModbusTcpClient("127.0.0.1", port=srv.tcp_port, timeout=0.3, retries=0)
        assert c.connect()
        try:
            assert not c.read_holding_registers(0, count=1, device_id=4).isError()
            slot.powered = False
            with pytest.raises(ModbusException):  # no answer at all (not an exception response)
                c.read_holding_registers(0, count=1, device_id=4)
            fresh = one_axis(t)
            slot.device, slot.powered = fresh, True
            c.close()
            assert c.connect()
            rr = c.read_holding_registers(0, count=1, device_id=4)
            assert not rr.isError() and fresh.transactions == 1
        finally:
            c.close()


@pytest.mark.parametrize("kind", CAMERA_FAULTS)
def test_camera_faults(kind):
    img = np.random.default_rng(0).integers(0, 200, (60, 80), dtype=np.uint8)
    out = damage(kind, img, np.random.default_rng(1))
    if kind == "camera_missing":
        assert out is None
        return
    assert out is not None and out.dtype == img.dtype
    if kind == "camera_black":
        assert not out.any()
    elif kind == "camera_saturated":
        assert (out == 255).all()
    elif kind == "camera_truncated":
        assert out.shape == img.shape and (out[-1] == 127).all() and not np.array_equal(out, img)
    else:
        assert out.shape != img.shape
    with pytest.raises(ValueError):
        damage("camera_upside_down", img, np.random.default_rng(1))
