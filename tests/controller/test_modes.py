"""The mode decision: night stow with a wake margin, DIFFUSE under overcast, else TRACK."""

import pytest

from controller.modes import ControlMode, decide_mode


@pytest.mark.parametrize(
    "el, min_el, overcast, mode, reason",
    [
        (30.0, 0.0, False, ControlMode.TRACK, "sun up"),
        (-1.9, 0.0, False, ControlMode.TRACK, "sun up"),  # within the 2-deg wake margin
        (-2.1, 0.0, False, ControlMode.STOW, "night"),
        (-2.1, 0.0, True, ControlMode.STOW, "night"),  # night outranks overcast
        (30.0, 0.0, True, ControlMode.DIFFUSE, "overcast"),
        (7.9, 10.0, False, ControlMode.STOW, "night"),  # min elevation raises the threshold
        (8.0, 10.0, False, ControlMode.TRACK, "sun up"),
    ],
)
def test_decide_mode(el, min_el, overcast, mode, reason):
    d = decide_mode(el, min_el, overcast=overcast)
    assert (d.mode, d.reason) == (mode, reason)


def test_wake_margin_is_a_parameter():
    assert decide_mode(-3.0, 0.0, wake_margin_deg=5.0).mode == ControlMode.TRACK
    assert decide_mode(-0.5, 0.0, wake_margin_deg=0.0).mode == ControlMode.STOW
