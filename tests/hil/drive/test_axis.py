import pytest

from hil.drive import AxisModel, AxisParams


def make(**kw):
    return AxisModel(AxisParams(**kw))


def test_moves_to_target_within_deadband_and_stops():
    ax = make(max_speed=1.0, accel=2.0, deadband=0.02, encoder_resolution=0.01)
    ax.target = 10.0
    ax.advance(30.0)
    assert ax.at_target and not ax.moving
    assert abs(ax.encoder - 10.0) <= 0.02 + 1e-9


def test_speed_and_acceleration_limits():
    ax = make(max_speed=0.5, accel=1.0, backlash=0.0)
    ax.target = 100.0
    ax.advance(0.2)
    assert ax.velocity == pytest.approx(0.2, abs=1e-6)  # accel-limited
    ax.advance(5.0)
    assert ax.velocity == pytest.approx(0.5)  # speed-limited
    assert ax.output == pytest.approx(0.5**2 / 2 + 0.5 * (5.2 - 0.5), abs=0.02)


def test_backlash_is_dead_travel_after_reversal():
    ax = make(backlash=0.5, deadband=0.0, encoder_resolution=0.0)
    ax.target = 5.0
    ax.advance(20)
    out_before = ax.output
    ax.target = 4.0
    ax.advance(0.3)  # the motor turns back but first crosses the play
    assert ax.output == pytest.approx(out_before)
    ax.advance(20)
    assert ax.output == pytest.approx(4.0, abs=1e-3)  # the loop closes on the output


def test_encoder_quantisation():
    ax = make(encoder_resolution=0.25)
    ax.output = 1.1
    assert ax.encoder == pytest.approx(1.0)


def test_jammed_motor_latches_stall_fault():
    ax = make(stall_time=1.0)
    ax.jammed = True
    ax.target = 10.0
    ax.advance(0.5)
    assert not ax.stalled
    ax.advance(1.0)
    assert ax.stalled and ax.output == 0.0
    assert not ax.clear_faults()  # still jammed
    ax.jammed = False
    assert ax.clear_faults()


def test_hard_limit_latches_and_stops():
    ax = make(soft_min=-10, soft_max=10, hard_min=-5, hard_max=5)  # misconfigured soft limits
    ax.target = 9.0
    ax.advance(30)
    assert ax.hard_limit and ax.output == pytest.approx(5.0)
    ax.target = 0.0
    assert ax.clear_faults()
    ax.advance(30)
    assert ax.output == pytest.approx(0.0, abs=0.03)
