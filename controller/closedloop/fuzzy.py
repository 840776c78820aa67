"""The paper's per-axis controller: a fuzzy self-tuning PID in incremental form.

Paper 003 drives each axis by "a fuzzy PID" from the sun's offset in the image but gives no
rules or gains.  This is the textbook table-driven design it refers to (the rule tables of
Liu Jinkun's *Advanced PID Control*, widely used in Chinese tracking papers):

* inputs: the error ``e`` (sun minus boresight along the axis, degrees) and its change per
  sample ``ec``, each scaled to the universe [-3, 3] and clipped;
* seven triangular terms NB NM NS ZO PS PM PB centred on -3..3 (a pair of terms fires);
* three 7 x 7 rule tables give the adjustments of Kp, Ki and Kd; defuzzification is the
  weighted mean of the fired rules' singletons (-3..3), scaled by ``dkp, dki, dkd / 3``;
* the PID is incremental, so its output is a setpoint step: ``du = Kp (e - e1) + Ki e +
  Kd (e - 2 e1 + e2)``.  For a drive that reaches its setpoint within a sample, ``Ki`` is
  the fraction of the error removed per sample (1 = dead-beat), ``Kp`` damps and ``Kd``
  anticipates.

No scikit-fuzzy: seven terms and three tables are 40 lines of numpy, with no dependency.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NB, NM, NS, ZO, PS, PM, PB = range(-3, 4)

#: Rows: e from NB to PB; columns: ec from NB to PB.
DKP = np.array(
    [
        [PB, PB, PM, PM, PS, ZO, ZO],
        [PB, PB, PM, PS, PS, ZO, NS],
        [PM, PM, PM, PS, ZO, NS, NS],
        [PM, PM, PS, ZO, NS, NM, NM],
        [PS, PS, ZO, NS, NS, NM, NM],
        [PS, ZO, NS, NM, NM, NM, NB],
        [ZO, ZO, NM, NM, NM, NB, NB],
    ],
    float,
)
DKI = np.array(
    [
        [NB, NB, NM, NM, NS, ZO, ZO],
        [NB, NB, NM, NS, NS, ZO, ZO],
        [NB, NM, NS, NS, ZO, PS, PS],
        [NM, NM, NS, ZO, PS, PM, PM],
        [NM, NS, ZO, PS, PS, PM, PB],
        [ZO, ZO, PS, PS, PM, PB, PB],
        [ZO, ZO, PS, PM, PM, PB, PB],
    ],
    float,
)
DKD = np.array(
    [
        [PS, NS, NB, NB, NB, NM, PS],
        [PS, NS, NB, NM, NM, NS, ZO],
        [ZO, NS, NM, NM, NS, NS, ZO],
        [ZO, NS, NS, NS, NS, NS, ZO],
        [ZO, ZO, ZO, ZO, ZO, ZO, ZO],
        [PB, NS, PS, PS, PS, PS, PB],
        [PB, PM, PM, PM, PS, PS, PB],
    ],
    float,
)


def memberships(x: float) -> np.ndarray:
    """Degrees of membership (7,) of ``x`` (clipped to [-3, 3]) in NB..PB (triangles)."""
    x = float(np.clip(x, -3.0, 3.0))
    return np.clip(1.0 - np.abs(x - np.arange(-3, 4)), 0.0, 1.0)


def infer(table: np.ndarray, e: float, ec: float) -> float:
    """Weighted mean (in [-3, 3]) of the rules fired by ``e`` and ``ec`` (both universes)."""
    w = np.outer(memberships(e), memberships(ec))
    return float((w * table).sum() / w.sum())


@dataclass(frozen=True)
class FuzzyPIDGains:
    """Base gains (per sample, dimensionless), the ranges of the fuzzy adjustments, the
    scalings of ``e`` and ``ec`` onto the universe (deg at which a term reaches PB), and
    the largest setpoint step per sample (deg)."""

    kp: float = 0.20
    ki: float = 0.60
    kd: float = 0.02
    dkp: float = 0.15
    dki: float = 0.30
    dkd: float = 0.02
    e_full_deg: float = 1.0
    ec_full_deg: float = 0.5
    max_step_deg: float = 3.0


class FuzzyPID:
    """One axis's fuzzy self-tuning PID (incremental); ``step(e)`` returns the setpoint step."""

    def __init__(self, gains: FuzzyPIDGains | None = None):
        self.gains = gains or FuzzyPIDGains()
        self.reset()

    def reset(self) -> None:
        """Forget the error history (after a gap: a stale e1 would kick the derivative)."""
        self.e1: float | None = None
        self.e2: float | None = None

    def gains_for(self, e: float, ec: float) -> tuple[float, float, float]:
        """(Kp, Ki, Kd) tuned by the rules for error ``e`` and change ``ec`` (deg)."""
        g = self.gains
        ue = 3.0 * e / g.e_full_deg
        uec = 3.0 * ec / g.ec_full_deg
        kp = g.kp + g.dkp / 3.0 * infer(DKP, ue, uec)
        ki = g.ki + g.dki / 3.0 * infer(DKI, ue, uec)
        kd = g.kd + g.dkd / 3.0 * infer(DKD, ue, uec)
        return max(kp, 0.0), float(np.clip(ki, 0.0, 1.0)), max(kd, 0.0)

    def step(self, e: float) -> float:
        """Setpoint increment (deg) for the error ``e`` (deg, sun minus boresight)."""
        e1 = self.e1 if self.e1 is not None else e
        e2 = self.e2 if self.e2 is not None else e1
        kp, ki, kd = self.gains_for(e, e - e1)
        du = kp * (e - e1) + ki * e + kd * (e - 2 * e1 + e2)
        self.e2, self.e1 = e1, e
        m = self.gains.max_step_deg
        return float(np.clip(du, -m, m))
