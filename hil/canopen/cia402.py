"""The CiA 402 power state machine of one axis, without any bus or motor.

:class:`Cia402StateMachine` decodes controlwords into transitions (CiA 402 "device control
commands"), latches faults and answers with the state bits of the statusword.  The node
(:mod:`hil.canopen.node`) connects it to the firmware: it halts the axis when the machine
leaves OPERATION ENABLED and executes fault resets.
"""

from __future__ import annotations

from dataclasses import dataclass

from firmware_protocol.canopen import STATE_BITS, Controlword, State402

S = State402


def command_of(cw: int) -> str:
    """Name of the device control command a controlword encodes (fault reset aside).

    Returns one of ``"disable_voltage"``, ``"quick_stop"``, ``"shutdown"``, ``"switch_on"``
    (also "disable operation") and ``"enable_operation"``.
    """
    if not cw & Controlword.ENABLE_VOLTAGE:
        return "disable_voltage"
    if not cw & Controlword.QUICK_STOP:
        return "quick_stop"
    if not cw & Controlword.SWITCH_ON:
        return "shutdown"
    if not cw & Controlword.ENABLE_OPERATION:
        return "switch_on"
    return "enable_operation"


#: (state, command) -> next state; pairs not listed leave the state unchanged.
TRANSITIONS: dict[tuple[State402, str], State402] = {
    (S.SWITCH_ON_DISABLED, "shutdown"): S.READY_TO_SWITCH_ON,  # 2
    (S.READY_TO_SWITCH_ON, "switch_on"): S.SWITCHED_ON,  # 3
    (S.READY_TO_SWITCH_ON, "enable_operation"): S.OPERATION_ENABLED,  # 3 + 4
    (S.READY_TO_SWITCH_ON, "disable_voltage"): S.SWITCH_ON_DISABLED,  # 7
    (S.READY_TO_SWITCH_ON, "quick_stop"): S.SWITCH_ON_DISABLED,  # 7
    (S.SWITCHED_ON, "enable_operation"): S.OPERATION_ENABLED,  # 4
    (S.SWITCHED_ON, "shutdown"): S.READY_TO_SWITCH_ON,  # 6
    (S.SWITCHED_ON, "disable_voltage"): S.SWITCH_ON_DISABLED,  # 10
    (S.SWITCHED_ON, "quick_stop"): S.SWITCH_ON_DISABLED,  # 10
    (S.OPERATION_ENABLED, "switch_on"): S.SWITCHED_ON,  # 5
    (S.OPERATION_ENABLED, "shutdown"): S.READY_TO_SWITCH_ON,  # 8
    (S.OPERATION_ENABLED, "disable_voltage"): S.SWITCH_ON_DISABLED,  # 9
    (S.OPERATION_ENABLED, "quick_stop"): S.QUICK_STOP_ACTIVE,  # 11
    (S.QUICK_STOP_ACTIVE, "disable_voltage"): S.SWITCH_ON_DISABLED,  # 12
    (S.QUICK_STOP_ACTIVE, "enable_operation"): S.OPERATION_ENABLED,  # 16
}


@dataclass
class Cia402StateMachine:
    """State of one axis's power state machine.

    Attributes
    ----------
    state : State402
        Current state; starts in NOT READY TO SWITCH ON until :meth:`boot`.
    controlword : int
        Last controlword received (edges of bits 4 and 7 are detected against it).
    fault_reset_edge : bool
        Set by :meth:`on_controlword` on a fault-reset rising edge in FAULT; the node
        clears the firmware fault and calls :meth:`fault_cleared` when it worked.
    """

    state: State402 = S.NOT_READY_TO_SWITCH_ON
    controlword: int = 0
    fault_reset_edge: bool = False

    def boot(self) -> None:
        """Transition 1: self-test done, power stage off."""
        if self.state == S.NOT_READY_TO_SWITCH_ON:
            self.state = S.SWITCH_ON_DISABLED

    def reset(self) -> None:
        """NMT reset: back to the power-up state."""
        self.state = S.NOT_READY_TO_SWITCH_ON
        self.controlword = 0
        self.fault_reset_edge = False

    def on_controlword(self, cw: int) -> tuple[State402, State402]:
        """Apply a controlword; return (old state, new state)."""
        prev, self.controlword = self.controlword, cw & 0xFFFF
        old = self.state
        rising_reset = bool(cw & Controlword.FAULT_RESET) and not prev & Controlword.FAULT_RESET
        if old == S.FAULT:
            if rising_reset:
                self.fault_reset_edge = True
        elif old not in (S.NOT_READY_TO_SWITCH_ON, S.FAULT_REACTION_ACTIVE):
            self.state = TRANSITIONS.get((old, command_of(cw)), old)
        return old, self.state

    def on_fault(self) -> bool:
        """A fault was detected: go through FAULT REACTION ACTIVE to FAULT (transitions 13,
        14).  Returns True when this is a new fault."""
        if self.state in (S.FAULT, S.FAULT_REACTION_ACTIVE):
            return False
        self.state = S.FAULT
        return True

    def fault_cleared(self) -> None:
        """Transition 15, after a fault reset found the cause gone."""
        self.fault_reset_edge = False
        if self.state == S.FAULT:
            self.state = S.SWITCH_ON_DISABLED

    @property
    def state_bits(self) -> int:
        """Statusword bits 0-3, 5 and 6 for the current state."""
        return STATE_BITS[self.state]

    @property
    def enabled(self) -> bool:
        return self.state == S.OPERATION_ENABLED
