"""The emulator answers real Modbus masters over a real pty."""

import minimalmodbus
import pytest
from pymodbus.client import ModbusSerialClient

from firmware_protocol import MAGIC, PROTOCOL_VERSION, decode, encode, register


@pytest.fixture
def client(pty_drive):
    fw, path, clock = pty_drive
    c = ModbusSerialClient(path, baudrate=115200, timeout=0.5, retries=0)
    assert c.connect()
    yield c, fw, clock, path
    c.close()


def test_pymodbus_reads_identification_and_writes_target(client):
    c, fw, clock, _ = client
    assert c.read_holding_registers(0, count=3, device_id=1).registers == [MAGIC, PROTOCOL_VERSION, 2]
    reg = register("TARGET_ANGLE")
    assert not c.write_registers(reg.address(1), encode(reg, 45.5), device_id=1).isError()
    assert fw.axes[1].target == pytest.approx(45.5)
    for beat in range(1, 13):  # keep the watchdog fed while it moves
        assert not c.write_register(register("HEARTBEAT").address(), beat, device_id=1).isError()
        clock.sleep(10)
    rr = c.read_holding_registers(register("ACTUAL_ANGLE").address(1), count=2, device_id=1)
    assert decode("ACTUAL_ANGLE", rr.registers) == pytest.approx(45.5, abs=0.03)


def test_exceptions_on_the_wire(client):
    c, *_ = client
    rr = c.write_registers(register("ACTUAL_ANGLE").address(0), [0, 1], device_id=1)
    assert rr.isError() and rr.exception_code == 2
    rr = c.write_register(register("MODE").address(0), 7, device_id=1)
    assert rr.isError() and rr.exception_code == 3
    rr = c.read_holding_registers(60, count=10, device_id=1)
    assert rr.isError() and rr.exception_code == 2


def test_foreign_slave_id_gets_no_answer(client):
    c, *_ = client
    from pymodbus.exceptions import ModbusIOException

    with pytest.raises(ModbusIOException):
        c.read_holding_registers(0, count=3, device_id=9)
    # The line is still usable afterwards.
    assert c.read_holding_registers(0, count=1, device_id=1).registers == [MAGIC]


def test_independent_master_minimalmodbus(pty_drive):
    fw, path, _clock = pty_drive
    inst = minimalmodbus.Instrument(path, 1)
    inst.serial.baudrate = 115200
    inst.serial.timeout = 0.5
    inst.close_port_after_each_call = True
    assert inst.read_registers(0, 3) == [MAGIC, PROTOCOL_VERSION, 2]
    inst.write_long(register("TARGET_ANGLE").address(0), -1500 + 200_000, signed=True)
    assert fw.axes[0].target == pytest.approx(198.5)
