"""Wire faults of the HIL: what each does to a Modbus reply (RTU frames, TCP ADUs)."""

import pytest

from hil.wire_faults import TCP_KINDS, WIRE_KINDS, WireFaults, crc16

# A real reply: slave 3, FC 3, 2 registers (0x0102, 0x0304), CRC.
BODY = bytes([3, 3, 4, 1, 2, 3, 4])
FRAME = BODY + crc16(BODY)
ADU = bytes([0, 7, 0, 0, 0, 7, 3, 3, 4, 1, 2, 3, 4])  # MBAP (tid 7, length 7, unit 3) + PDU


def crc_ok(frame: bytes) -> bool:
    return crc16(frame[:-2]) == frame[-2:]


def test_crc16_is_modbus():
    # the example of the Modbus over serial line specification (read 2 registers at 0x6B)
    assert crc16(bytes.fromhex("11 03 00 6B 00 03")) == bytes.fromhex("76 87")
    assert crc_ok(FRAME)


@pytest.mark.parametrize("seed", range(5))
def test_rtu_faults_damage_the_reply_as_named(seed):
    w = WireFaults(seed=seed, late_s=(0.6, 0.9), split_gap_s=(0.01, 0.02))
    assert w.apply_rtu("modbus_timeout", FRAME) == []
    [(d, bad)] = w.apply_rtu("crc_error", FRAME)
    assert d == 0 and bad[:-2] == FRAME[:-2] and not crc_ok(bad)
    [(_, garbled)] = w.apply_rtu("garbled_reply", FRAME)
    assert garbled != FRAME
    (d1, a), (d2, b) = w.apply_rtu("split_reply", FRAME)
    assert a + b == FRAME and a and b and d1 == 0 and 0.01 <= d2 <= 0.02
    [(late, same)] = w.apply_rtu("late_reply", FRAME)
    assert same == FRAME and 0.6 <= late <= 0.9
    [(_, other)] = w.apply_rtu("wrong_id_reply", FRAME)
    assert other[0] != FRAME[0] and other[1:-2] == FRAME[1:-2] and crc_ok(other)


def test_garbled_rtu_reply_never_passes_as_the_original():
    w = WireFaults(seed=1)
    for _ in range(200):
        [(_, g)] = w.apply_rtu("garbled_reply", FRAME)
        tail = g[-len(FRAME) :]
        # either the frame itself is damaged (its CRC fails), or line noise precedes it
        assert not crc_ok(tail) or len(g) > len(FRAME)


def test_tcp_faults_damage_the_header_never_the_data_silently():
    w = WireFaults(seed=2, tcp=True)
    assert w.apply_tcp("modbus_timeout", ADU) == []
    [(_, other)] = w.apply_tcp("wrong_id_reply", ADU)
    assert other[6] != ADU[6] and other[7:] == ADU[7:]
    for _ in range(100):
        [(_, g)] = w.apply_tcp("garbled_reply", ADU)
        assert g != ADU
        assert g[9:] == ADU[9:]  # the register values are never what is changed
    (_, a), (gap, b) = w.apply_tcp("split_reply", ADU)
    assert a + b == ADU and gap > 0


def test_rates_are_per_reply_seeded_and_counted():
    rates = {"crc_error": 0.1, "split_reply": 0.1}
    a, b = WireFaults(rates, seed=4), WireFaults(rates, seed=4)
    picks = [a.pick(3) for _ in range(2000)]
    assert picks == [b.pick(3) for _ in range(2000)]  # repeatable
    n = sum(p is not None for p in picks)
    assert 300 < n < 450  # about 1 - 0.9 * 0.9 = 19 %
    assert sum(a.injected.values()) == n
    events = a.drain()
    assert len(events) == n and all(e.device_id == 3 for e in events) and not a.drain()


def test_a_forced_fault_hits_every_reply_of_its_slave_only():
    w = WireFaults()
    w.forced[2] = "modbus_timeout"
    assert [w.pick(2) for _ in range(3)] == ["modbus_timeout"] * 3
    assert w.pick(3) is None
    w.forced[None] = "late_reply"
    assert w.pick(3) == "late_reply"


def test_kinds_and_probabilities_are_checked():
    with pytest.raises(ValueError, match="unknown wire fault"):
        WireFaults({"cosmic_ray": 0.1})
    with pytest.raises(ValueError, match="outside"):
        WireFaults({"crc_error": 1.5})
    assert "crc_error" not in WireFaults({"crc_error": 0.5}, tcp=True).rates
    assert set(TCP_KINDS) < set(WIRE_KINDS)
