"""Soft limits and stow angle are written in an order a firmware with interlocks accepts."""

from hypothesis import given
from hypothesis import strategies as st

from controller.drives.base import soft_limit_steps

angle = st.integers(-180, 180).map(float)


@st.composite
def axis_setting(draw):
    """Soft limits (min < max) and a stow angle within them, degrees."""
    lo = draw(angle)
    hi = draw(angle.filter(lambda h: h > lo))
    stow = draw(st.floats(lo, hi))
    return (lo, hi), stow


def apply(state, step):
    """One step on (lo, hi, stow), every intermediate state checked as the firmware does
    (a pair is written min first, as the CANopen backend must)."""
    (lo, hi), stow = state
    if isinstance(step, tuple):
        for a, b in ((step[0], hi), step):
            assert a < b and a <= stow <= b, (a, b, stow)
        return step, stow
    assert lo <= step <= hi, (lo, hi, step)
    return (lo, hi), step


@given(axis_setting(), axis_setting())
def test_every_state_on_the_way_is_valid(old, new):
    state = old
    for step in soft_limit_steps(old[0], new[0], new[1]):
        state = apply(state, step)
    assert state == new


def test_no_write_is_wasted():
    assert soft_limit_steps((0, 90), (0, 90), 45) == [45]
    assert soft_limit_steps((0, 90), (5, 85), 80) == [80, (5, 85)]
    assert soft_limit_steps((0, 90), (5, 95), 92) == [(0, 95), 92, (5, 95)]
    assert soft_limit_steps((0, 90), None, 30) == [30]
    assert soft_limit_steps((0, 90), (10, 20), None) == [(10, 20)]
