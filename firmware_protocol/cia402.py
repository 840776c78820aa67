"""CiA 402 power state machine vocabulary: controlword and statusword bits, the states and
how a statusword names one (shared by the drive emulator and the controller's 402 master)."""

from __future__ import annotations

from enum import IntEnum, IntFlag


class Controlword(IntFlag):
    """CiA 402 controlword (0x6040) bits; bits 4-6 are profile-position specific."""

    SWITCH_ON = 1 << 0
    ENABLE_VOLTAGE = 1 << 1
    QUICK_STOP = 1 << 2  # active low: 0 requests a quick stop
    ENABLE_OPERATION = 1 << 3
    NEW_SET_POINT = 1 << 4  # rising edge latches 0x607A
    CHANGE_IMMEDIATELY = 1 << 5
    RELATIVE = 1 << 6
    FAULT_RESET = 1 << 7  # rising edge
    HALT = 1 << 8


#: Controlword for "enabled, no new set-point" and for "enabled, new set-point now".
CW_ENABLE_OPERATION = 0x000F
CW_NEW_SET_POINT = CW_ENABLE_OPERATION | Controlword.NEW_SET_POINT | Controlword.CHANGE_IMMEDIATELY


class Statusword(IntFlag):
    """CiA 402 statusword (0x6041) bits."""

    READY_TO_SWITCH_ON = 1 << 0
    SWITCHED_ON = 1 << 1
    OPERATION_ENABLED = 1 << 2
    FAULT = 1 << 3
    VOLTAGE_ENABLED = 1 << 4
    QUICK_STOP = 1 << 5  # active low: 0 while a quick stop is active
    SWITCH_ON_DISABLED = 1 << 6
    WARNING = 1 << 7
    REMOTE = 1 << 9
    TARGET_REACHED = 1 << 10
    INTERNAL_LIMIT = 1 << 11
    SET_POINT_ACK = 1 << 12  # profile position: set-point acknowledge
    FOLLOWING_ERROR = 1 << 13


class State402(IntEnum):
    """CiA 402 power state machine states."""

    NOT_READY_TO_SWITCH_ON = 0
    SWITCH_ON_DISABLED = 1
    READY_TO_SWITCH_ON = 2
    SWITCHED_ON = 3
    OPERATION_ENABLED = 4
    QUICK_STOP_ACTIVE = 5
    FAULT_REACTION_ACTIVE = 6
    FAULT = 7


#: State -> statusword bits 0-3, 5, 6 (the "state" part; mask 0x6F).
STATE_BITS: dict[State402, int] = {
    State402.NOT_READY_TO_SWITCH_ON: 0x00,
    State402.SWITCH_ON_DISABLED: 0x40,
    State402.READY_TO_SWITCH_ON: 0x21,
    State402.SWITCHED_ON: 0x23,
    State402.OPERATION_ENABLED: 0x27,
    State402.QUICK_STOP_ACTIVE: 0x07,
    State402.FAULT_REACTION_ACTIVE: 0x0F,
    State402.FAULT: 0x08,
}


def state_from_statusword(sw: int) -> State402 | None:
    """Decode the power state from a statusword (None when no pattern matches)."""
    for state, bits in STATE_BITS.items():
        mask = (
            0x4F
            if state
            in (
                State402.NOT_READY_TO_SWITCH_ON,
                State402.SWITCH_ON_DISABLED,
                State402.FAULT,
                State402.FAULT_REACTION_ACTIVE,
            )
            else 0x6F
        )
        if sw & mask == bits & mask:
            return state
    return None
