"""The CiA 402 power state machine, without a bus."""

import pytest

from firmware_protocol.canopen import STATE_BITS, state_from_statusword
from firmware_protocol.canopen import State402 as S
from hil.canopen.cia402 import Cia402StateMachine, command_of


@pytest.mark.parametrize(
    "cw, cmd",
    [
        (0x00, "disable_voltage"),
        (0x80, "disable_voltage"),
        (0x02, "quick_stop"),
        (0x06, "shutdown"),
        (0x07, "switch_on"),
        (0x0F, "enable_operation"),
        (0x1F, "enable_operation"),
    ],
)
def test_controlword_commands(cw, cmd):
    assert command_of(cw) == cmd


def test_power_up_to_operation_enabled_and_back():
    sm = Cia402StateMachine()
    assert sm.state == S.NOT_READY_TO_SWITCH_ON
    sm.on_controlword(0x06)  # ignored before self-test
    assert sm.state == S.NOT_READY_TO_SWITCH_ON
    sm.boot()
    assert sm.state == S.SWITCH_ON_DISABLED
    sm.on_controlword(0x0F)  # enable from SOD is not a transition
    assert sm.state == S.SWITCH_ON_DISABLED
    for cw, state in [
        (0x06, S.READY_TO_SWITCH_ON),
        (0x07, S.SWITCHED_ON),
        (0x0F, S.OPERATION_ENABLED),
        (0x07, S.SWITCHED_ON),
        (0x0F, S.OPERATION_ENABLED),
        (0x02, S.QUICK_STOP_ACTIVE),
        (0x0F, S.OPERATION_ENABLED),
        (0x06, S.READY_TO_SWITCH_ON),
        (0x0F, S.OPERATION_ENABLED),
        (0x00, S.SWITCH_ON_DISABLED),
    ]:
        sm.on_controlword(cw)
        assert sm.state == state, hex(cw)
        assert state_from_statusword(sm.state_bits) == state


def test_fault_needs_a_reset_edge_and_a_cleared_cause():
    sm = Cia402StateMachine()
    sm.boot()
    for cw in (0x06, 0x07, 0x0F):
        sm.on_controlword(cw)
    assert sm.on_fault() is True
    assert sm.on_fault() is False  # latched: not a new fault
    assert sm.state == S.FAULT
    sm.on_controlword(0x0F)  # no transition out of FAULT but by reset
    assert sm.state == S.FAULT and not sm.fault_reset_edge
    sm.on_controlword(0x8F)
    assert sm.fault_reset_edge
    sm.fault_cleared()
    assert sm.state == S.SWITCH_ON_DISABLED


def test_every_state_has_a_distinct_statusword_pattern():
    for state, bits in STATE_BITS.items():
        assert state_from_statusword(bits | 0x0200) == state
