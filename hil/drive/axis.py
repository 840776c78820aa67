"""Physics of one slewing-drive axis: motor, gearbox backlash, output encoder, limits.

The position loop of the firmware closes on the output-side encoder, so backlash shows
as a short dead travel after each reversal rather than as a pointing error; what remains
is encoder quantisation and the loop's deadband (see :class:`AxisParams`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_protocol.registers import FACTORY


@dataclass
class AxisParams:
    """Mechanical and loop parameters of an axis (degrees, seconds).

    Attributes
    ----------
    max_speed : float
        Speed limit, deg/s (slewing drives: 0.1-2 deg/s).
    accel : float
        Acceleration and deceleration, deg/s^2.
    backlash : float
        Total play of the gear train, deg.
    encoder_resolution : float
        Output encoder quantum, deg.
    deadband : float
        The loop stops when |target - encoder| <= deadband, deg.
    soft_min, soft_max : float
        Soft limits (targets are clamped to them), deg.
    hard_min, hard_max : float
        Limit switches: crossing one latches a HARD_LIMIT fault, deg.
    stow_angle : float
        Where STOW mode sends the axis, deg.
    stall_time : float
        Commanded without motion this long -> STALL fault, s.
    initial_angle : float
        Position at power-up, deg.
    """

    max_speed: float = FACTORY["MAX_SPEED"]
    accel: float = 2.0
    backlash: float = 0.05
    encoder_resolution: float = 0.01
    deadband: float = 0.02
    soft_min: float = FACTORY["SOFT_LIMIT_MIN"]
    soft_max: float = FACTORY["SOFT_LIMIT_MAX"]
    hard_min: float = -185.0
    hard_max: float = 185.0
    stow_angle: float = FACTORY["STOW_ANGLE"]
    stall_time: float = 2.0
    initial_angle: float = 0.0


class AxisModel:
    """State and dynamics of one axis; :meth:`step` integrates with a fixed small dt."""

    DT = 0.02  # s, integration step while moving

    def __init__(self, params: AxisParams):
        self.p = params
        self.motor = params.initial_angle  # gear input, in output degrees
        self.output = params.initial_angle  # panel side
        self.velocity = 0.0  # motor side, deg/s
        self.target = params.initial_angle
        self.enabled = True
        self.jammed = False  # fault injection: motor cannot turn
        self.stall_timer = 0.0
        self.stalled = False
        self.hard_limit = False
        #: Fault injection: a limit switch reads pressed (a trip latches HARD_LIMIT, and it
        #: cannot be cleared while the switch stays pressed).
        self.limit_stuck = False
        #: Fault injection: an encoder glitch, deg added to the reading (the position loop
        #: closes on it, so the panel really moves off by this much while it lasts).
        self.encoder_offset = 0.0
        self.hot = False  # fault injection: the motor's temperature over its limit
        self.overheated = False  # latched OVERTEMPERATURE (the motor off until cleared)
        #: Fault injection: a load over the motor's current limit (a seized bearing, a drift
        #: of snow against the motion): the drive trips OVERCURRENT as soon as it drives.
        self.overloaded = False
        self.overcurrent = False  # latched OVERCURRENT (the motor off until cleared)
        #: The encoder is referenced (STATUS HOMED); clear while a homing runs.
        self.homed = True
        #: A homing runs: the axis drives to its index, then on to ``_after_homing``.
        self.homing = False
        self._after_homing = 0.0
        self._homed_before = True

    # -- measurements -------------------------------------------------------------
    @property
    def encoder(self) -> float:
        q = self.p.encoder_resolution
        reading = self.output + self.encoder_offset
        return round(reading / q) * q if q > 0 else reading

    @property
    def at_target(self) -> bool:
        return abs(self.target - self.encoder) <= self.p.deadband + 1e-9 and self.velocity == 0

    @property
    def moving(self) -> bool:
        return self.velocity != 0.0

    # -- the master's target, and homing ----------------------------------------------
    @property
    def commanded(self) -> float:
        """The target the master set (deg): during a homing, where the axis goes after it."""
        return self._after_homing if self.homing else self.target

    def command(self, angle: float) -> None:
        """A new target from the master; a homing under way keeps it for afterwards."""
        if self.homing:
            self._after_homing = angle
        else:
            self.target = angle

    def index(self) -> float:
        """Where the encoder's reference mark is: its zero, or the soft limit nearest it."""
        return min(max(0.0, self.p.soft_min), self.p.soft_max)

    def start_homing(self) -> None:
        """HOME: drive to the index (HOMED clear meanwhile), reference the encoder there,
        then drive on to the target the master set."""
        if not self.homing:
            self._after_homing, self._homed_before = self.target, self.homed
            self.homing, self.homed = True, False
        self.target = self.index()

    def abort_homing(self) -> None:
        """A stow, a halt or maintenance ends a homing: the old reference stands."""
        if self.homing:
            self.homing, self.homed = False, self._homed_before
            self.target = self._after_homing

    def _homing_done(self) -> bool:
        """At rest on the index during a homing: referenced; True when there is more to do."""
        if not (self.homing and self.at_target and self.enabled) or self.faulted:
            return False
        self.homing, self.homed = False, True
        self.target = self._after_homing
        return not self.at_target

    @property
    def faulted(self) -> bool:
        return self.stalled or self.hard_limit or self.overheated or self.overcurrent

    # -- dynamics -----------------------------------------------------------------
    def advance(self, seconds: float) -> None:
        """Integrate ``seconds`` of motion (returns early once at rest)."""
        if self.hot:  # the drive's thermal protection: the motor off, the fault latched
            self.overheated = True
        remaining = seconds
        while remaining > 1e-12:
            if self._at_rest() and not self._homing_done():
                return
            dt = min(self.DT, remaining)
            self._step(dt)
            remaining -= dt

    def _at_rest(self) -> bool:
        if not self.enabled or self.faulted:
            self.velocity = 0.0
            return True
        return self.at_target

    def _step(self, dt: float) -> None:
        p = self.p
        error = self.target - self.encoder
        if abs(error) <= p.deadband:
            # Inside the deadband: brake to a stop.
            dv = p.accel * dt
            self.velocity = (
                0.0 if abs(self.velocity) <= dv else self.velocity - math.copysign(dv, self.velocity)
            )
        else:
            # Braking curve: the fastest speed from which we can still stop at the target.
            v_cmd = math.copysign(min(p.max_speed, math.sqrt(2 * p.accel * abs(error))), error)
            dv = p.accel * dt
            self.velocity += max(-dv, min(dv, v_cmd - self.velocity))
        if self.overloaded:
            # The current limit trips within milliseconds of driving, long before a stall.
            self.velocity = 0.0
            self.overcurrent = True
            return
        if self.jammed:
            # Current flows but nothing turns: the firmware notices after stall_time.
            self.velocity = 0.0
            self.stall_timer += dt
            if self.stall_timer >= p.stall_time:
                self.stalled = True
            return
        self.stall_timer = 0.0
        self.motor += self.velocity * dt
        half = p.backlash / 2
        if self.motor - self.output > half:
            self.output = self.motor - half
        elif self.motor - self.output < -half:
            self.output = self.motor + half
        if not p.hard_min <= self.output <= p.hard_max:
            self.hard_limit = True
            self.velocity = 0.0
            self.output = min(max(self.output, p.hard_min), p.hard_max)
            self.motor = self.output

    def trip_limit(self) -> None:
        """Fault injection: a limit switch trips (and stays pressed until released)."""
        self.limit_stuck = True
        self.hard_limit = True
        self.velocity = 0.0

    def clear_faults(self) -> bool:
        """Clear latched faults whose cause is gone; True when clear."""
        if self.stalled and not self.jammed:
            self.stalled = False
            self.stall_timer = 0.0
        if self.hard_limit and not self.limit_stuck and self.p.soft_min <= self.target <= self.p.soft_max:
            # The switch is still pressed, but the new target leads back inside.
            self.hard_limit = False
        if self.overheated and not self.hot:  # cooled down
            self.overheated = False
        # An over-current trip always clears: the next motion trips again while the load lasts.
        self.overcurrent = False
        return not (self.stalled or self.hard_limit or self.overheated)
