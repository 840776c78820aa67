"""The configuration a drive holds: what the controller writes at start-up (watchdog,
soft limits, stow angles), as read back from the drive.

``run`` reads it back after writing it, so that a firmware that acknowledges writes and
keeps its own values (its watchdog off, its factory limits) is not driven as configured;
``check`` shows it beside what ``run`` would write.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class DriveConfiguration:
    """One drive's configuration as it reports it (:meth:`DriveLink.read_configuration`;
    ``DriveLink.configuration`` keeps the last read-back after a configuration).

    heartbeat_timeout_s : the watchdog's timeout (s); 0: the watchdog is off.
    soft_limits : per axis, (min, max) a target may ask for (deg).
    stow_angles : per axis, where STOW sends the axis (deg).
    max_speeds : per axis, the position loop's speed limit (deg/s); empty when not read.
    heartbeat_producer : CANopen only, the node id whose heartbeat the watchdog consumes
        (None where the link has no such notion, or the axes disagree: see ``producers``).
    producers : CANopen only, that node id per axis.
    """

    heartbeat_timeout_s: float
    soft_limits: tuple[tuple[float, float], ...]
    stow_angles: tuple[float, ...]
    heartbeat_producer: int | None = None
    producers: tuple[int, ...] = ()
    max_speeds: tuple[float, ...] = ()

    def describe(self) -> str:
        """One line for an operator: ``watchdog 180 s; limits [-55, 55] deg; stow 0 deg``."""
        dog = "watchdog off" if self.heartbeat_timeout_s <= 0 else f"watchdog {self.heartbeat_timeout_s:g} s"
        if self.producers and self.heartbeat_timeout_s > 0:
            dog += " on node " + "/".join(str(p) for p in sorted(set(self.producers)))
        limits = " / ".join(f"[{lo:g}, {hi:g}]" for lo, hi in self.soft_limits)
        stows = " / ".join(f"{a:g}" for a in self.stow_angles)
        text = f"{dog}; limits {limits} deg; stow {stows} deg"
        if self.max_speeds:
            text += "; speed " + " / ".join(f"{v:g}" for v in self.max_speeds) + " deg/s"
        return text


@dataclass(frozen=True)
class Tolerances:
    """How far a read-back may be from the value written: one step of the drive's units
    (s, deg)."""

    timeout_s: float
    limit_deg: float
    stow_deg: float


def differences(
    got: DriveConfiguration,
    tol: Tolerances,
    *,
    heartbeat_timeout_s: float | None = None,
    soft_limits: Sequence[tuple[float, float]] | None = None,
    stow_angles: Sequence[float] | None = None,
    producer: int | None = None,
) -> list[tuple[str, str, str]]:
    """Where ``got`` differs from what is given (None: not compared).

    Returns
    -------
    list of (what, held, wanted)
        ``("watchdog", "0 s", "180 s")``, ``("axis 1 soft limits", "[-90, 90]", "[5, 85]")``,
        ``("axis 0 stow angle", "0", "30")``, ``("watchdog's producer", "node 5", "node 127")``.
    """
    out = []
    if heartbeat_timeout_s is not None and abs(got.heartbeat_timeout_s - heartbeat_timeout_s) > tol.timeout_s:
        out.append(("watchdog", f"{got.heartbeat_timeout_s:g} s", f"{heartbeat_timeout_s:g} s"))
    if producer is not None and any(p != producer for p in got.producers):
        held = "/".join(f"node {p}" for p in got.producers)
        out.append(("watchdog's producer", held, f"node {producer}"))
    for k, (lo, hi) in enumerate(soft_limits or ()):
        g_lo, g_hi = got.soft_limits[k] if k < len(got.soft_limits) else (float("nan"),) * 2
        if not (abs(g_lo - lo) <= tol.limit_deg and abs(g_hi - hi) <= tol.limit_deg):
            out.append((f"axis {k} soft limits", f"[{g_lo:g}, {g_hi:g}]", f"[{lo:g}, {hi:g}]"))
    for k, angle in enumerate(stow_angles or ()):
        g = got.stow_angles[k] if k < len(got.stow_angles) else float("nan")
        if not abs(g - angle) <= tol.stow_deg:
            out.append((f"axis {k} stow angle", f"{g:g}", f"{angle:g}"))
    return out


def not_taken(label: str, diffs: list[tuple[str, str, str]]) -> str:
    """The read-back's error: ``label: configuration not taken: watchdog reads 0 s, 50 s written``."""
    return f"{label}: configuration not taken: " + "; ".join(
        f"{what} {'read' if what.endswith('limits') else 'reads'} {held}, {wanted} written"
        for what, held, wanted in diffs
    )
