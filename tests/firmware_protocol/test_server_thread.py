"""The Modbus server thread both servers run on (HIL devices and SunSpec)."""

import pytest
from pymodbus.client import ModbusTcpClient
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from firmware_protocol.server_thread import ServerThread, ServerThreadError


def tcp_server(port: int = 0) -> ModbusTcpServer:
    device = SimDevice(
        id=1, simdata=[SimData(0, count=4, values=[11, 22, 33, 44], datatype=DataType.REGISTERS)]
    )
    return ModbusTcpServer(device, address=("127.0.0.1", port))


def test_serves_on_a_free_port_until_stopped():
    with ServerThread(tcp_server, name="test-server") as thread:
        assert thread.port and thread._thread.name == "test-server"
        client = ModbusTcpClient("127.0.0.1", port=thread.port, timeout=2, retries=0)
        assert client.connect()
        assert client.read_holding_registers(0, count=4, device_id=1).registers == [11, 22, 33, 44]
        client.close()
    assert not thread._thread.is_alive()
    client = ModbusTcpClient("127.0.0.1", port=thread.port, timeout=0.5, retries=0)
    assert not client.connect()  # nobody listens any more


def test_a_failing_factory_is_reported_by_start():
    def broken():
        raise ValueError("no such device")

    thread = ServerThread(broken)
    with pytest.raises(ServerThreadError, match="no such device") as err:
        thread.start()
    assert isinstance(err.value.__cause__, ValueError)
    thread.stop()  # quiet after a failed start


def test_an_address_in_use_is_reported_by_start():
    with ServerThread(tcp_server) as first:
        second = ServerThread(lambda: tcp_server(first.port))
        with pytest.raises(ServerThreadError):
            second.start()
        second.stop()
