"""The emulated drive refuses PDO parameter writes that CiA 301 forbids, over SDO on the
virtual bus, with a real device's abort codes; canopen's own ``PdoMap.save`` order passes."""

from __future__ import annotations

import pytest
from canopen.sdo import SdoAbortedError

from hil.canopen.pdo_rules import (
    ABORT_NO_OBJECT,
    ABORT_NOT_MAPPABLE,
    ABORT_PDO_LENGTH,
    ABORT_UNSUPPORTED,
    ABORT_VALUE_RANGE,
    COB_INVALID,
)

from .rig import emulated, master, node402, wait_for

TPDO1_COM, TPDO1_MAP, RPDO1_COM, RPDO1_MAP = 0x1800, 0x1A00, 0x1400, 0x1600


def _entry(index: int, sub: int, bits: int) -> int:
    return index << 16 | sub << 8 | bits


def _refused(node, index: int, sub: int, value: int) -> int:
    with pytest.raises(SdoAbortedError) as exc:
        node.sdo[index][sub].raw = value
    return exc.value.code


def test_a_master_that_skips_a_step_or_maps_too_much_is_refused():
    with emulated() as (_fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        cob = node.sdo[TPDO1_COM][1].raw
        assert not cob & COB_INVALID  # TPDO1 is in use
        # a mapping changed while the PDO is valid, an inhibit time, another ID
        assert _refused(node, TPDO1_MAP, 0, 0) == ABORT_UNSUPPORTED
        assert _refused(node, TPDO1_COM, 3, 100) == ABORT_VALUE_RANGE
        assert _refused(node, TPDO1_COM, 1, 0x2A5) == ABORT_VALUE_RANGE
        # reserved transmission types, 29-bit and restricted identifiers
        for bad in (241, 251, 252):
            assert _refused(node, TPDO1_COM, 2, bad) == ABORT_VALUE_RANGE
        assert _refused(node, TPDO1_COM, 1, COB_INVALID | 1 << 29 | 0x2A5) == ABORT_VALUE_RANGE

        node.sdo[TPDO1_COM][1].raw = cob | COB_INVALID  # step 1: make it invalid
        assert _refused(node, TPDO1_COM, 1, 0x605) == ABORT_VALUE_RANGE  # an SDO server's ID
        assert _refused(node, TPDO1_MAP, 1, _entry(0x6041, 0, 16)) == ABORT_UNSUPPORTED  # count first
        node.sdo[TPDO1_MAP][0].raw = 0
        assert _refused(node, TPDO1_MAP, 1, _entry(0x5FFF, 0, 16)) == ABORT_NO_OBJECT
        assert _refused(node, TPDO1_MAP, 1, _entry(0x6041, 3, 16)) == ABORT_NO_OBJECT  # no sub-index 3
        assert _refused(node, TPDO1_MAP, 1, _entry(0x6041, 0, 8)) == ABORT_NOT_MAPPABLE  # a part of it
        assert _refused(node, TPDO1_MAP, 1, _entry(0x1000, 0, 32)) == ABORT_NOT_MAPPABLE  # device type
        assert _refused(node, TPDO1_MAP, 1, _entry(0x0007, 0, 32)) == ABORT_NOT_MAPPABLE  # dummies: RPDO
        for k, index in enumerate((0x6064, 0x606C, 0x6041), start=1):  # 32 + 32 + 16 bits
            node.sdo[TPDO1_MAP][k].raw = _entry(index, 0, 16 if index == 0x6041 else 32)
        assert _refused(node, TPDO1_MAP, 0, 3) == ABORT_PDO_LENGTH  # 80 bits
        assert _refused(node, TPDO1_MAP, 0, 9) == ABORT_PDO_LENGTH  # more entries than it has
        node.sdo[TPDO1_MAP][0].raw = 2
        node.sdo[TPDO1_COM][1].raw = cob  # valid again, 64 bits


def test_an_rpdo_maps_only_what_can_be_written_and_may_skip_bytes():
    with emulated() as (_fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        cob = node.sdo[RPDO1_COM][1].raw
        node.sdo[RPDO1_COM][1].raw = cob | COB_INVALID
        node.sdo[RPDO1_MAP][0].raw = 0
        assert _refused(node, RPDO1_MAP, 1, _entry(0x6064, 0, 32)) == ABORT_NOT_MAPPABLE  # read-only
        assert _refused(node, RPDO1_COM, 2, 253) == ABORT_VALUE_RANGE
        node.sdo[RPDO1_MAP][1].raw = _entry(0x0006, 0, 16)  # two bytes skipped
        node.sdo[RPDO1_MAP][2].raw = _entry(0x607A, 0, 32)
        node.sdo[RPDO1_MAP][0].raw = 2
        node.sdo[RPDO1_COM][1].raw = cob


def test_canopens_save_reconfigures_a_tpdo_that_then_reports():
    with emulated() as (_fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        node.nmt.state = "PRE-OPERATIONAL"
        tpdo = node.tpdo[1]
        tpdo.clear()
        tpdo.add_variable(0x6064)
        tpdo.add_variable(0x6041)
        tpdo.trans_type = 255
        tpdo.event_timer = 50
        tpdo.inhibit_time = 10
        tpdo.enabled = True
        tpdo.save()
        assert node.sdo[TPDO1_MAP][0].raw == 2
        assert node.sdo[TPDO1_MAP][1].raw == _entry(0x6064, 0, 32)
        node.nmt.state = "OPERATIONAL"
        before = tpdo.timestamp
        assert wait_for(lambda: tpdo.timestamp != before)
        assert len(tpdo.data) == 6
