"""Manual overrides that outlive a restart of ``run``.

A SCADA's ``Ctl = Manual`` (SunSpec model 601) holds a tracker at its ``ElCtl``/``AzCtl``
until ``Ctl = Automatic``: a row parked for maintenance, for cleaning, or for a broken
module.  Kept in memory only, it was gone after a restart (a power blip, an upgrade, a
watchdog restart of the service), and the row started tracking again under the hands that
had parked it.  So ``run`` keeps the overrides in force in ``DIR/overrides.json`` of its
``--state`` folder (by tracker name, the axis angles as the controller holds them) and puts
them back before its first cycle, each said in a warning line.  The controller's own stows
(wind, snow, hail, a lost link) still come first, as before the restart.

An entry for a tracker the plant no longer has, or with angles that are not the tracker's
axes, is said and ignored; the angles are clamped into the tracker's present travel.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

from controller.config import DualAxisTracker
from controller.loop import Controller
from heliotrack.kept_record import note_record, read_record

log = logging.getLogger("heliotrack.run")

FILE_NAME = "overrides.json"


def kept(ctl: Controller) -> dict[str, list[float]]:
    """The Manual overrides in force, by tracker name (axis angles, deg)."""
    return {ctl.trackers[i].cfg.name: [float(a) for a in v] for i, v in sorted(ctl.overrides.items())}


def note_overrides(
    ctl: Controller, folder: Path | None, last: dict[str, list[float]] | None
) -> dict[str, list[float]] | None:
    """Write the overrides to ``folder / FILE_NAME`` when they differ from ``last`` (the ones
    last written; None: not yet by this process); return the ones now on record."""
    path = None if folder is None else folder / FILE_NAME
    return note_record(path, "overrides", kept(ctl), last, "the Manual overrides")


def restore_overrides(ctl: Controller, folder: Path | None) -> dict[str, list[float]]:
    """Put the overrides of ``folder / FILE_NAME`` back in force, each said in a warning line;
    return them as now held (empty without a folder, a file, or a readable one)."""
    if folder is None:
        return {}
    path = folder / FILE_NAME
    index = {tr.cfg.name: i for i, tr in enumerate(ctl.trackers)}
    for name, angles in sorted(read_record(path, "overrides", "Manual override").items()):
        i = index.get(name)
        axes = ctl.trackers[i].cfg.axes if i is not None else 0
        if i is None or not _angles(angles, axes):
            why = "no tracker of this plant" if i is None else f"not {axes} angle(s) in deg"
            log.warning("%s: %r: %r is %s; ignored", path, name, angles, why)
            continue
        if isinstance(ctl.trackers[i].cfg, DualAxisTracker):
            ctl.set_override(i, "Manual", float(angles[1]), float(angles[0]))
        else:
            ctl.set_override(i, "Manual", float(angles[0]), None)
        held = ", ".join(f"{a:g}" for a in ctl.overrides[i])
        log.warning("%s: Manual at %s deg, set before the restart: held until Automatic", name, held)
    return kept(ctl)


def _angles(value: object, axes: int) -> bool:
    """A list of ``axes`` finite numbers."""
    return (
        isinstance(value, list)
        and len(value) == axes
        and all(isinstance(a, int | float) and not isinstance(a, bool) and math.isfinite(a) for a in value)
    )
