"""Snow and hail stow requests that outlive a restart of ``run``.

A SCADA's ``StowReq`` (SunSpec model 64601) or an operator's request holds the plant
stowed until it is withdrawn.  Kept in memory only, it was gone after a restart (a power
blip, an upgrade, a watchdog restart of the service): the plant went back to tracking
under the snow it had been stowed for, and ``StowReq`` read 0.  So ``run`` keeps the
requests in force in ``DIR/stow-requests.json`` (written when they change) and takes them
back at the next start.  The ``[stow] flag_file`` is not kept: it is read every cycle.

A file that cannot be read is said in one warning line and ignored: the requests are then
SCADA's to give again, and the file is rewritten at the first change.
"""

from __future__ import annotations

import logging
from pathlib import Path

from controller.loop import Controller
from heliotrack.kept_record import note_record, read_record

log = logging.getLogger("heliotrack.run")

FILE_NAME = "stow-requests.json"
#: The sources whose requests are kept (the flag file's is read again every cycle).
KEPT = ("sunspec", "operator")
KINDS = ("snow", "hail")


def kept(ctl: Controller) -> dict[str, str]:
    """The requests in force that a restart must not lose, by source."""
    return {s: k for s, k in sorted(ctl.safety.requests.items()) if s in KEPT}


def note_stow_requests(
    ctl: Controller, folder: Path | None, last: dict[str, str] | None
) -> dict[str, str] | None:
    """Write the kept requests to ``folder / FILE_NAME`` when they differ from ``last`` (the
    ones last written; None: not yet by this process); return the ones now on record."""
    path = None if folder is None else folder / FILE_NAME
    return note_record(path, "requests", kept(ctl), last, "the stow requests")


def restore_stow_requests(ctl: Controller, folder: Path | None) -> dict[str, str]:
    """Put the requests of ``folder / FILE_NAME`` back in force, each said in a warning
    line; return them (empty without a folder, a file, or a readable one)."""
    if folder is None:
        return {}
    path = folder / FILE_NAME
    requests = read_record(path, "requests", "stow request")
    out = {}
    for source, kind in sorted(requests.items()):
        if source in KEPT and kind in KINDS:
            ctl.safety.request(source, kind)
            out[source] = kind
            log.warning("%s stow requested by %s before the restart: in force until withdrawn", kind, source)
        else:
            log.warning("%s: %r: %r is not a kept stow request; ignored", path, source, kind)
    return out
