"""The CANopen object dictionary and EDS agree with the Modbus register map."""

from __future__ import annotations

import io

import canopen
import pytest
from canopen.objectdictionary import eds as eds_format

from firmware_protocol import REGISTER_MAP, Fault, register
from firmware_protocol.canopen import (
    AXIS_MIRROR_BASE,
    EDS_NAME,
    FAULT_ERROR_CODES,
    GLOBAL_MIRROR_BASE,
    NOT_MAPPED,
    OBJECTS,
    RPDOS,
    STANDARD_ALIASES,
    TPDOS,
    TYPE_BITS,
    entry,
    mirror_index,
    register_entry,
)
from firmware_protocol.eds import eds
from firmware_protocol.generate import GENERATED_DIR, artefacts

_SIGNED = {"int16", "int32"}


@pytest.fixture(scope="module")
def od():
    return eds_format.import_eds(io.StringIO(eds()), 5)


def test_eds_is_a_generated_artefact_and_committed():
    assert EDS_NAME in artefacts()
    assert (GENERATED_DIR / EDS_NAME).read_text() == eds()


def test_committed_eds_loads_in_canopen():
    od = canopen.import_od(str(GENERATED_DIR / EDS_NAME), 9)
    assert od[0x1800][1].default == 0x189  # $NODEID resolved
    assert od.device_information.nr_of_TXPDO == len(TPDOS)


def test_mandatory_and_402_objects_exist(od):
    for index in (
        0x1000,
        0x1001,
        0x1016,
        0x1017,
        0x1018,
        0x1400,
        0x1401,
        0x1600,
        0x1601,
        0x1800,
        0x1A00,
        0x1801,
        0x1A01,
        0x603F,
        0x6040,
        0x6041,
        0x6060,
        0x6061,
        0x6064,
        0x606C,
        0x607A,
        0x607D,
        0x6081,
        0x6502,
    ):
        assert index in od, hex(index)
    assert od[0x1000].default & 0xFFFF == 0x192  # CiA 402 device
    assert od[0x6502].default & 1  # profile position supported


def test_every_register_has_an_object_with_its_scale_and_type(od):
    for reg in REGISTER_MAP:
        if reg.name in NOT_MAPPED:
            continue
        idx = mirror_index(reg)
        base = AXIS_MIRROR_BASE if reg.per_axis else GLOBAL_MIRROR_BASE
        assert idx == base + reg.offset
        var = od[idx]
        assert len(var) == 16 * reg.words
        assert (var.data_type in (0x2, 0x3, 0x4)) == (reg.type in _SIGNED), reg.name
        assert var.factor == pytest.approx(reg.scale), reg.name
        # One write path per quantity: mirrors of standard-aliased registers are read-only.
        assert var.writable == (reg.writable and reg.name not in STANDARD_ALIASES), reg.name


def test_standard_aliases_carry_the_register_scale(od):
    for name, (index, sub) in STANDARD_ALIASES.items():
        reg = register(name)
        e = entry(index, sub)
        assert e.register == name
        assert register_entry(name) == e
        if name == "HEARTBEAT_TIMEOUT":
            assert e.scale == 0.001  # ms in the low 16 bits of 0x1016:1
            continue
        assert e.scale == pytest.approx(reg.scale), name
        var = od[index] if not sub else od[index][sub]
        assert var.factor == pytest.approx(reg.scale)
        assert len(var) >= 16 * reg.words  # standard objects may be wider
    assert register("TARGET_ANGLE").scale == 0.001  # positions in 0.001 deg, as on Modbus


def test_pdo_mappings_are_consistent(od):
    for layouts, com, mapping in ((RPDOS, 0x1400, 0x1600), (TPDOS, 0x1800, 0x1A00)):
        for p in layouts:
            rec = od[mapping + p.number - 1]
            assert rec[0].default == len(p.objects)
            bits = 0
            for k, (index, sub) in enumerate(p.objects):
                value = rec[k + 1].default
                assert value >> 16 == index and (value >> 8) & 0xFF == sub
                var = od[index] if not sub else od[index][sub]
                assert value & 0xFF == len(var)
                assert var.pdo_mappable
                bits += len(var)
            assert bits <= 64
            assert od[com + p.number - 1][1].default == p.cob_base + 5
    mapped = {i for p in RPDOS + TPDOS for i, _ in p.objects}
    # What canopen's BaseNode402 needs to run without SDO fallbacks:
    assert {0x6040, 0x6041, 0x6060, 0x6061, 0x607A, 0x6064} <= mapped


def test_fault_codes_cover_every_fault():
    assert set(FAULT_ERROR_CODES) == set(Fault)
    assert len(set(FAULT_ERROR_CODES.values())) == len(Fault)
    assert FAULT_ERROR_CODES[Fault.NONE] == 0


def test_entry_types_are_known():
    for o in OBJECTS:
        for e in o.entries:
            assert e.data_type in TYPE_BITS or e.data_type == 0x9
            if isinstance(e.default, int) and e.data_type in TYPE_BITS and e.data_type >= 0x5:
                assert 0 <= e.default < 1 << TYPE_BITS[e.data_type]


def test_eds_defaults_are_the_reference_drives_power_up_values(od):
    """A firmware-side audit's case: the EDS gave 0 for the consumer heartbeat (the watchdog
    off, refused outside MAINTENANCE), 0 / 0 for the position window (inverted, refused) and
    0 for the profile velocity; a tool writing the defaults broke the drive's setup."""
    from firmware_protocol.canopen import MASTER_NODE_ID
    from firmware_protocol.registers import FACTORY
    from hil.drive import AxisParams, DriveFirmware

    assert od[0x1016][1].default == (MASTER_NODE_ID << 16) | round(FACTORY["HEARTBEAT_TIMEOUT"] * 1000)
    lo, hi = od[0x607D][1].default, od[0x607D][2].default
    assert lo < hi and (lo, hi) == (
        round(FACTORY["SOFT_LIMIT_MIN"] * 1000),
        round(FACTORY["SOFT_LIMIT_MAX"] * 1000),
    )
    assert od[0x6081].default == round(FACTORY["MAX_SPEED"] * 1000)
    # what the emulated drive holds at power-up
    fw = DriveFirmware([AxisParams()], lambda: 0.0)
    assert fw.heartbeat_timeout == FACTORY["HEARTBEAT_TIMEOUT"]
    p = fw.axes[0].p
    assert (p.soft_min, p.soft_max, p.max_speed) == (
        FACTORY["SOFT_LIMIT_MIN"],
        FACTORY["SOFT_LIMIT_MAX"],
        FACTORY["MAX_SPEED"],
    )
