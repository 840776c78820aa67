"""Learning a row's misalignment (mounting or encoder offset) from the panel-mounted camera.

Each frame in which the camera sees the sun measures the offset directly, independently of
how the drive got where it is:

    z = position + error - reference

``position``: the drive's reported axis angle (its encoder); ``error``: the camera's angular
offset of the sun from the boresight along that axis; ``reference``: the angle an aligned
row would have for the ephemeris sun.  For a row whose panel sits ``delta`` off its encoder,
``z = -delta`` (plus the ephemeris's own error, which the estimate absorbs as well): the
setpoint correction that points it at the sun.

The estimate is a scalar Kalman filter with a random walk (offsets drift slowly: thermal,
settling), so it converges in tens of frames, keeps its value through cloud gaps, and
follows a slow change.  Measurements more than ``gate_sigma`` sigmas off are refused
(a false detection); a long run of refusals means the offset itself moved (maintenance,
a slipped coupling) and the filter restarts from the next measurement.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from ..atomic import atomic_write


@dataclass
class OffsetLearner:
    """Per-axis offset estimate (deg).

    meas_sigma_deg : one-sigma noise of one measurement ``z``.
    drift_deg_per_sqrt_h : random-walk rate of the true offset.
    initial_sigma_deg : prior uncertainty (the offset is unknown at first).
    gate_sigma : refusal threshold; ``restart_after`` consecutive refusals restart it.
    start_frames : the gate applies once this many frames were taken since the start or a
        restart (one frame turns a 3-deg prior into 0.05 deg: a first frame 0.44 deg off, a
        sun under cloud, had the right ones refused for an hour).
    """

    meas_sigma_deg: float = 0.05
    drift_deg_per_sqrt_h: float = 0.02
    initial_sigma_deg: float = 3.0
    gate_sigma: float = 5.0
    restart_after: int = 20
    estimate_deg: float = 0.0
    variance: float = 9.0
    last_t: float | None = None
    accepted: int = 0
    refused: int = 0
    refused_run: int = 0
    start_frames: int = 5
    since_start: int = 0

    def __post_init__(self) -> None:
        if self.last_t is None and self.accepted == 0:
            self.variance = self.initial_sigma_deg**2

    @property
    def sigma_deg(self) -> float:
        return math.sqrt(self.variance)

    @property
    def learned(self) -> bool:
        """True once the estimate is better than a fifth of a degree."""
        return self.accepted > 0 and self.sigma_deg < 0.2

    def predict(self, t: float) -> None:
        if self.last_t is not None and t > self.last_t:
            self.variance += self.drift_deg_per_sqrt_h**2 * (t - self.last_t) / 3600.0
        self.last_t = t if self.last_t is None else max(self.last_t, t)

    def admits(self, t: float, z_deg: float, *, sigma_deg: float | None = None) -> bool:
        """Whether a measurement ``z`` (deg) at POSIX ``t`` passes the gate (``sigma_deg`` as
        for :meth:`update`); changes nothing."""
        if not math.isfinite(z_deg):
            return False
        if self.accepted == 0 or self.since_start < self.start_frames:
            return True
        var = self.variance
        if self.last_t is not None and t > self.last_t:
            var += self.drift_deg_per_sqrt_h**2 * (t - self.last_t) / 3600.0
        r = max(self.meas_sigma_deg, sigma_deg or 0.0) ** 2
        return (z_deg - self.estimate_deg) ** 2 <= self.gate_sigma**2 * (var + r)

    def update(self, t: float, z_deg: float, *, veto: bool = False, sigma_deg: float | None = None) -> bool:
        """Add one measurement ``z`` (deg) at POSIX ``t``; False when it was refused: by the
        gate, or by ``veto`` (the frame was refused on another axis of the same row).
        ``sigma_deg``: the measurement's own one-sigma, when it is larger than
        ``meas_sigma_deg`` (a sun seen far off the camera's axis)."""
        if not math.isfinite(z_deg):
            return False
        self.predict(t)
        r = max(self.meas_sigma_deg, sigma_deg or 0.0) ** 2
        innov = z_deg - self.estimate_deg
        if veto or not self.admits(t, z_deg, sigma_deg=sigma_deg):
            self.refused += 1
            self.refused_run += 1
            if self.refused_run >= self.restart_after:
                self.estimate_deg, self.variance = z_deg, self.initial_sigma_deg**2
                self.refused_run = self.since_start = 0
            return False
        k = self.variance / (self.variance + r)
        self.estimate_deg += k * innov
        self.variance *= 1.0 - k
        self.accepted += 1
        self.since_start += 1
        self.refused_run = 0
        return True

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> OffsetLearner:
        known = {k: d[k] for k in cls.__dataclass_fields__ if k in d}
        if "since_start" not in d and d.get("accepted", 0) > 0:
            known["since_start"] = known.get(
                "start_frames", cls.start_frames
            )  # saved before the field: started
        return cls(**known)


class MisalignmentStore:
    """The learned offsets of every row and axis, persisted atomically as JSON.

    ``store.learner("row-7", "rotation")`` returns (and creates) that axis's learner.
    """

    def __init__(self, path: str | Path | None = None):
        self.path = Path(path) if path is not None else None
        self.learners: dict[str, dict[str, OffsetLearner]] = {}
        #: What loading the file said (a warning), "" when it loaded or did not exist yet.
        self.note = ""
        if self.path is not None and self.path.exists():
            self._load(self.path)

    def _load(self, path: Path) -> None:
        """The file's learners; a file that is not one is moved aside (kept, never lost) and
        the offsets are learned anew; one that cannot be read is left alone and not written."""
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as exc:
            self.note = f"{path}: learned row offsets not read ({exc}); learning anew, not saved"
            self.path = None
            return
        try:
            self.learners = parse_learners(json.loads(text))
        except (ValueError, TypeError, AttributeError) as exc:
            self.learners = {}
            aside = path.with_name(f"{path.name}.invalid-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}")
            try:
                path.rename(aside)
                self.note = f"{path}: not a file of learned row offsets ({exc}); kept it as {aside.name}; learning anew"
            except OSError as err:
                self.note = f"{path}: not a file of learned row offsets ({exc}); could not move it aside ({err.strerror}); learning anew, not saved"
                self.path = None

    def learner(self, row: str, axis: str) -> OffsetLearner:
        return self.learners.setdefault(row, {}).setdefault(axis, OffsetLearner())

    def offsets(self) -> dict[str, dict[str, float]]:
        return {row: {ax: lr.estimate_deg for ax, lr in axes.items()} for row, axes in self.learners.items()}

    def save(self, path: str | Path | None = None) -> Path:
        p = Path(path) if path is not None else self.path
        if p is None:
            raise ValueError("MisalignmentStore.save: no path")
        data = {
            "rows": {
                row: {ax: lr.to_dict() for ax, lr in axes.items()} for row, axes in self.learners.items()
            }
        }
        return atomic_write(p, json.dumps(data, indent=1) + "\n")


def parse_learners(data: object) -> dict[str, dict[str, OffsetLearner]]:
    """The learners of a saved ``{"rows": {row: {axis: learner}}}``.

    Raises
    ------
    ValueError
        Not that shape, a key a learner does not have, or a learner whose estimate or
        variance is not a finite number (a variance must be > 0).
    """
    if not isinstance(data, dict) or not isinstance(data.get("rows", {}), dict):
        raise ValueError('no {"rows": {...}} object')
    out: dict[str, dict[str, OffsetLearner]] = {}
    for row, axes in data.get("rows", {}).items():
        if not isinstance(axes, dict) or not all(isinstance(d, dict) for d in axes.values()):
            raise ValueError(f"row {row!r}: not an object of axes")
        for ax, d in axes.items():
            unknown = sorted(set(d) - set(OffsetLearner.__dataclass_fields__))
            if unknown:  # a misspelt key would reset what it names to its default, unsaid
                raise ValueError(f"row {row!r}, axis {ax!r}: unknown key(s) {', '.join(unknown)}")
            bad = [
                k
                for k, v in d.items()
                if not (v is None and k == "last_t")
                and (isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v))
            ]
            if bad:
                raise ValueError(f"row {row!r}, axis {ax!r}: {', '.join(bad)} not a finite number")
        out[row] = {ax: OffsetLearner.from_dict(d) for ax, d in axes.items()}
        for ax, lr in out[row].items():
            if lr.variance <= 0:
                raise ValueError(f"row {row!r}, axis {ax!r}: variance {lr.variance!r}, not > 0")
    return out
