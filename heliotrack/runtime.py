"""What ``heliotrack run`` and ``check`` share: which devices a command may use, the state
folder, and leaving every drive at its safe position.

- :func:`refuse_hil` (``run``, ``check``) and :func:`require_hil` (``simulate``): a plant
  file names real devices, a scenario file only the simulator's (``"hil"``), and each
  command refuses the other kind in one line that names the key.
- :func:`use_state_folder`: ``--state DIR``, the one place that decides where learned
  state lives (the SQLite store ``DIR/heliotrack.sqlite`` unless ``[store] path`` names
  one, the sun-path file ``DIR/sunpath.json`` unless ``[sunpath] state`` does, the record
  of the last shutdown).
- :func:`claim_state_folder`: one ``run`` per state folder (an exclusive lock on
  ``DIR/.lock``); a second is refused in one line naming the first's pid.
- :func:`go_safe`: every drive commanded to its tracker's ``safe_position`` (``stow`` or
  ``hold``) and confirmed by reading it back; the trackers stowed so are recorded in the
  state folder, so that the next start resumes them (a stow it did not command the loop
  otherwise leaves alone, as a local switch's).
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

from controller.atomic import atomic_write
from controller.config import Config
from controller.drives.base import DriveCommError, DriveNoAnswer
from controller.drives.links import CanopenLink, LinkConfig, ModbusRtuLink, ModbusTcpLink
from controller.errors import ConfigError, UserError
from controller.health import implausible_axes
from controller.loop import Controller
from controller.records import TrackerRuntime
from controller.safety import clamp_targets
from firmware_protocol import Command, Mode, Status

from .bus_claims import Held, hold

log = logging.getLogger("heliotrack.run")

#: The key that names a link's device, per link kind.
_DEVICE_KEY: dict[type[LinkConfig], str] = {
    ModbusRtuLink: "port",
    ModbusTcpLink: "host",
    CanopenLink: "channel",
}


def _device_key(link: LinkConfig) -> str:
    for cls, key in _DEVICE_KEY.items():
        if isinstance(link, cls):
            return key
    return "kind"


def load_plant(path: str | Path, command: str = "run") -> Config:
    """Read a plant file for ``run`` or ``check``: the schema, then :func:`refuse_hil`.

    Raises
    ------
    ConfigError
        The file is invalid, is a simulator scenario (a ``[hil]`` table), or names a
        simulator device.
    """
    from controller.config import load_config

    try:
        config: Config = load_config(path)
    except ConfigError as exc:
        if exc.key == "hil":
            raise ConfigError(
                exc.file,
                "hil",
                f"a plant file for heliotrack {command}, with no [hil] table (a [hil] table makes "
                "a scenario for heliotrack simulate)",
            ) from None
        raise
    refuse_hil(config, command)
    return config


def refuse_hil(config: Config, command: str = "run") -> None:
    """A plant file for ``run`` or ``check`` names real devices only.

    Raises
    ------
    ConfigError
        A link or the camera names a device only ``heliotrack simulate`` provides.
    """
    for i, link in enumerate(config.links):
        if link.is_hil:
            key = _device_key(link)
            raise ConfigError(
                config.file,
                f"links[{i}].{key}",
                f'a real device for heliotrack {command} ("hil" names an emulator only '
                "heliotrack simulate provides)",
                getattr(link, key, link.kind),
            )
    for name in ("hotspot", "fisheye"):
        table = getattr(config, name)
        if table is not None and table.frames == "hil":
            raise ConfigError(
                config.file,
                f"{name}.frames",
                f"a camera for heliotrack {command}: device:N, a stream URL, a video file or a folder "
                '("hil" is the renderer only heliotrack simulate provides)',
                "hil",
            )


def require_hil(config: Config) -> None:
    """A scenario for ``simulate`` names the simulator's devices only: it runs every drive
    and sensor on emulators, so a real port, host or bus would be silently ignored.

    Raises
    ------
    ConfigError
        A link names a real device (or a Modbus TCP port the simulator would not use).
    """
    for i, link in enumerate(config.links):
        key = _device_key(link)
        if not link.is_hil:
            raise ConfigError(
                config.file,
                f"links[{i}].{key}",
                '"hil" in a simulation, which runs on emulators (to drive real devices use heliotrack run)',
                getattr(link, key, link.kind),
            )
        if isinstance(link, ModbusTcpLink) and link.tcp_port not in (0, 502):
            raise ConfigError(
                config.file,
                f"links[{i}].tcp_port",
                '0 or 502 with host = "hil" (the simulator serves on a free port of 127.0.0.1; '
                "to reach a real endpoint use heliotrack run)",
                link.tcp_port,
            )


# -- the state folder ---------------------------------------------------------------------------
@dataclass(frozen=True)
class StateFolder:
    """Where ``run`` keeps what it learned and what it left (``--state DIR``)."""

    path: Path

    @property
    def store(self) -> Path:
        """The SQLite store (learned state and history), unless ``[store] path`` names one."""
        return self.path / "heliotrack.sqlite"

    @property
    def sunpath(self) -> Path:
        """The sun-path filter's state file, unless ``[sunpath] state`` names one: read once
        into a new store, and where the state goes when the store cannot be opened."""
        return self.path / "sunpath.json"

    @property
    def misalignment(self) -> Path:
        """The panel-mounted closed loop's learned row offsets, unless ``[closedloop] state``
        names a file."""
        return self.path / "misalignment.json"

    @property
    def shutdown(self) -> Path:
        """The trackers the last shutdown stowed (resumed by the next start)."""
        return self.path / "shutdown.json"

    @property
    def foreign_stows(self) -> Path:
        """The trackers seen in someone else's stow, kept up to date while ``run`` runs, so
        that a start after ``kill -9`` or a power cut still knows whose stow it was."""
        return self.path / "foreign-stows.json"

    @property
    def lock(self) -> Path:
        """Locked by the ``run`` using the folder, and holding its pid (:func:`claim_state_folder`)."""
        return self.path / ".lock"


def use_state_folder(config: Config, folder: Path | None) -> tuple[Config, StateFolder | None]:
    """Create (if needed) and check the state folder; the config with its state files in it:
    the store (``[store] path``), the sun-path state file (``[sunpath] state``) and the
    closed loop's learned offsets (``[closedloop] state``), each unless the plant file names
    one.

    Without a folder, the config is unchanged (state persists only where the plant file
    says).

    Raises
    ------
    ConfigError
        ``--state`` cannot be created or written.
    """
    if folder is None:
        return config, None
    try:
        folder = folder.expanduser().resolve()
    except (RuntimeError, OSError) as exc:  # a symlink loop, a "~user" of no one
        raise ConfigError(None, "--state", f"a usable folder path ({exc})", str(folder)) from None
    if folder.exists() and not folder.is_dir():
        raise ConfigError(None, "--state", "a folder (this is a file)", str(folder))
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(
            None, "--state", f"a folder that can be created ({exc.strerror})", str(folder)
        ) from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ConfigError(None, "--state", "a folder this user can write", str(folder))
    state = StateFolder(folder)
    if config.store.path is None:
        config = replace(config, store=replace(config.store, path=state.store))
    if config.sunpath.state is None:
        config = replace(config, sunpath=replace(config.sunpath, state=state.sunpath))
    cl = config.closedloop
    if cl is not None and cl.state is None:
        config = replace(config, closedloop=replace(cl, state=state.misalignment))
    return config, state


@contextmanager
def claim_state_folder(state: StateFolder | None) -> Iterator[None]:
    """Hold an exclusive lock on ``state.lock`` for the block (``run``: its whole life).

    Two ``run`` on one folder would both drive the plant's drives and overwrite each
    other's records.  ``flock`` rather than a pid file: the kernel lets go when the process
    dies however it dies (``kill -9``, a power cut), so a stale file never blocks a start.
    The pid written into it is for the refusal's message only.

    Raises
    ------
    UserError
        Another process holds the lock (the message names its pid), or the lock file
        cannot be created.
    """
    if state is None:
        yield
        return
    try:
        fd = os.open(state.lock, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise ConfigError(
            None,
            "--state",
            f"a folder where {state.lock.name} can be created ({exc.strerror})",
            str(state.path),
        ) from None
    try:
        try:
            hold(fd, str(state.lock))
        except Held as held:
            raise UserError(
                f"--state {state.path}: in use by another heliotrack run (pid {held.pid})"
            ) from None
        yield
    finally:
        os.close(fd)  # releases the lock; the file stays (removing it would race a new start)


def note_foreign_stows(
    ctl: Controller, state: StateFolder | None, last: frozenset[str] | None
) -> frozenset[str] | None:
    """Write the trackers now in someone else's stow to ``state.foreign_stows`` when the set
    has changed since ``last`` (the set last written; None: not written yet by this
    process, so write); returns the set now on record.

    Without it, a drive stowed by a local switch while the controller was killed (no
    shutdown record) says COMM_LOST once its watchdog has found it stowed, and older
    firmware (without WATCHDOG_STOW) makes that look like the watchdog's stow, which the
    next start would resume.  Written on change only: one small file a stow, not a cycle.
    """
    now = frozenset(tr.cfg.name for tr in ctl.trackers if tr.health.foreign_stow)
    if state is None or now == last:
        return last
    try:
        atomic_write(state.foreign_stows, json.dumps({"time": time.time(), "trackers": sorted(now)}) + "\n")
    except OSError as exc:  # said once for this set, not at every cycle
        log.warning("%s: not written (%s)", state.foreign_stows, exc)
    return now


def _move_aside(path: Path) -> str:
    """Rename an unusable record ``<name>.unusable-<UTC>`` (kept for a look, never deleted,
    as the store and the sun-path state are); what was done, for the warning."""
    aside = path.with_name(f"{path.name}.unusable-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}")
    try:
        path.rename(aside)
        return f"kept as {aside.name}"
    except OSError as err:
        return f"could not move it aside: {err.strerror}"


def _load_names(path: Path, keys: dict[str, bool]) -> dict[str, set[str]] | None:
    """The lists of tracker names under ``keys`` (key: required) of a JSON record of the
    state folder; None when there is no record.

    Raises
    ------
    ValueError
        The record cannot be used (not JSON, nested too deeply, a key missing or not a list
        of names); the message names the file and why, and the file has been moved aside.
    """
    if not (path.exists() or path.is_symlink()):  # a dangling or looping link is a bad record
        return None
    try:
        record = json.loads(path.read_text())
        if not isinstance(record, dict):
            raise TypeError("expected a JSON object")
        out = {}
        for key, required in keys.items():
            names = record[key] if required else record.get(key, [])
            if not (isinstance(names, list) and all(isinstance(n, str) for n in names)):
                raise TypeError(f"{key}: expected a list of tracker names, got {type(names).__name__}")
            out[key] = set(names)
        return out
    except (OSError, ValueError, TypeError, KeyError, RecursionError) as exc:
        why = "nested too deeply" if isinstance(exc, RecursionError) else f"{type(exc).__name__}: {exc}"
        raise ValueError(f"{path}: unreadable ({why}): {_move_aside(path)}") from None


def _recorded_foreign_stows(state: StateFolder) -> set[str]:
    """The names :func:`note_foreign_stows` last wrote (none when absent or unreadable)."""
    try:
        record = _load_names(state.foreign_stows, {"trackers": True})
    except ValueError as exc:  # rewritten by the first cycle
        log.warning("%s; no foreign stow known from it", exc)
        return set()
    return set() if record is None else record["trackers"]


def resume_last_shutdown(ctl: Controller, state: StateFolder | None) -> list[str]:
    """Mark the trackers the last shutdown stowed as stowed by us (the loop resumes them),
    and those it found in someone else's stow as such (left so even if their watchdog has
    fired since); returns the names resumed.  The shutdown record is used once.  Without
    one (``kill -9``, a power cut), the trackers last seen in someone else's stow
    (:func:`note_foreign_stows`) are marked as such."""
    if state is None:
        return []
    try:
        record = _load_names(state.shutdown, {"stowed": True, "left": False})
    except ValueError as exc:
        log.warning("%s; no stow resumed from it", exc)
        record = {"stowed": set(), "left": _recorded_foreign_stows(state)}
    if record is None:  # no shutdown record: kill -9 or a power cut
        record = {"stowed": set(), "left": _recorded_foreign_stows(state)}
    names, left = record["stowed"], record["left"]
    resumed = [tr.cfg.name for tr in ctl.trackers if tr.cfg.name in names]
    for tr in ctl.trackers:
        if tr.cfg.name in names:
            tr.health.stowed_by_us = True
        elif tr.cfg.name in left:  # someone else's stow: a COMM_LOST since is not the watchdog's
            tr.health.foreign_stow = True
    try:
        state.shutdown.unlink()
    except OSError:
        pass
    if resumed:
        log.info("resuming %d tracker(s) the last shutdown stowed: %s", len(resumed), ", ".join(resumed))
    return resumed


# -- safe positions -------------------------------------------------------------------------------
@dataclass
class SafeOutcome:
    """What one drive was left doing at shutdown."""

    tracker: str
    wanted: str  # "stow" or "hold"
    confirmed: bool
    detail: str
    positions_deg: tuple[float, ...] = ()
    #: False for a stow this controller did not command (left so, not resumed at the next start)
    ours: bool = True


def _angles(values) -> str:
    return ", ".join(f"{v:.2f}" for v in values)


async def _safe_one(ctl: Controller, tr: TrackerRuntime, deadline: float) -> SafeOutcome:
    want = tr.cfg.safe_position
    drive = tr.drive
    if not tr.configured:
        await drive.connect()  # a drive the loop had lost: one more try
    try:
        st = await drive.read_state()
    except DriveCommError as exc:  # it answers, but not with a state to trust: stow it anyway
        if isinstance(exc, DriveNoAnswer):
            raise  # silent: its watchdog is all there is (go_safe says so)
        await drive.command(Command.STOW)
        tr.health.stowed_by_us = True
        return SafeOutcome(tr.cfg.name, want, False, f"state unreadable ({exc}): STOW sent, not read back")
    if any(a.mode == Mode.MAINTENANCE for a in st.axes):  # in someone's hands: whatever the flags say
        pos = tuple(a.actual_deg for a in st.axes)
        return SafeOutcome(tr.cfg.name, want, True, "in MAINTENANCE: left so", pos, ours=False)
    wrong = implausible_axes(st, tr.cfg.soft_limits)
    if want == "hold" and wrong:  # holding there would drive it to a limit
        want = "stow"
        log.warning("%s: %s: stowed at shutdown instead of held", tr.cfg.name, wrong)
    if want == "hold":
        if any(a.mode == Mode.STOW for a in st.axes):
            # a weather or watchdog stow in force: the safest place, left so
            return SafeOutcome(
                tr.cfg.name, want, True, "already stowed: left so", tuple(a.actual_deg for a in st.axes)
            )
        targets = clamp_targets(tr.cfg, [a.actual_deg for a in st.axes])
        st = await drive.exchange(targets)
        ok = all(abs(a.target_deg - x) <= 0.02 for a, x in zip(st.axes, targets))
        detail = f"holding at {_angles(targets)} deg" + ("" if ok else " (target not read back)")
        return SafeOutcome(tr.cfg.name, want, ok, detail, tuple(a.actual_deg for a in st.axes))
    # whose stow it is: the loop's rule (controller.health.DriveHealth.assess)
    ours = tr.health.stowed_by_us or tr.health.watchdog_stow
    ours = ours or any(a.status & Status.WATCHDOG_STOW for a in st.axes)
    ours = ours or (not tr.health.foreign_stow and any(a.status & Status.COMM_LOST for a in st.axes))
    if all(a.mode in (Mode.STOW, Mode.MAINTENANCE) for a in st.axes) and not ours:
        # a local switch's or a maintenance panel's stow: theirs to lift, so neither
        # commanded again nor recorded for the next start to resume
        pos = tuple(a.actual_deg for a in st.axes)
        modes = "/".join(sorted({a.mode.name for a in st.axes}))
        detail = f"already in {modes}, not by us: left so (not resumed at the next start)"
        return SafeOutcome(tr.cfg.name, want, True, detail, pos, ours=False)
    await drive.command(Command.STOW)
    tr.health.stowed_by_us = True
    while True:
        st = await drive.read_state()
        if all(a.mode in (Mode.STOW, Mode.MAINTENANCE) for a in st.axes):
            pos = tuple(a.actual_deg for a in st.axes)
            modes = "/".join(sorted({a.mode.name for a in st.axes}))
            where = "" if wrong else f" from {_angles(pos)} deg"
            return SafeOutcome(tr.cfg.name, want, True, f"stowing{where} (mode {modes} read back)", pos)
        if time.monotonic() >= deadline:
            modes = ", ".join(a.mode.name for a in st.axes)
            return SafeOutcome(tr.cfg.name, want, False, f"STOW not read back (modes {modes})")
        await asyncio.sleep(0.05)


async def go_safe(
    ctl: Controller, timeout_s: float = 3.0, state: StateFolder | None = None
) -> list[SafeOutcome]:
    """Command every drive to its tracker's ``safe_position`` at once and read it back.

    ``stow``: the STOW command, confirmed when every axis reads back in STOW mode (the
    drive then travels there by itself).  ``hold``: the axes' present angles as targets,
    confirmed when the drive reads them back; a drive already in STOW is left so.  A drive
    that does not answer within ``timeout_s`` is reported (its own watchdog stows it
    within ``control.heartbeat_timeout_s``).  The trackers stowed are recorded in
    ``state`` for the next start.
    """
    deadline = time.monotonic() + timeout_s

    async def one(tr: TrackerRuntime) -> SafeOutcome:
        try:
            return await _safe_one(ctl, tr, deadline)
        except (DriveCommError, OSError, ValueError) as exc:
            return SafeOutcome(tr.cfg.name, tr.cfg.safe_position, False, f"no answer: {exc}")
        except Exception as exc:  # noqa: BLE001 - one drive's surprise must not leave the others unsafe
            log.error("%s: safe position failed: %s", tr.cfg.name, exc, exc_info=exc)
            return SafeOutcome(
                tr.cfg.name, tr.cfg.safe_position, False, f"failed: {type(exc).__name__}: {exc}"
            )

    tasks = {tr.cfg.name: asyncio.ensure_future(one(tr)) for tr in ctl.trackers}
    await asyncio.wait(tasks.values(), timeout=max(deadline - time.monotonic(), 0.1))
    outcomes = []
    hb = ctl.config.control.heartbeat_timeout_s
    for tr in ctl.trackers:
        task = tasks[tr.cfg.name]
        if task.done() and not task.cancelled():
            out = task.result()
        else:
            task.cancel()
            out = SafeOutcome(tr.cfg.name, tr.cfg.safe_position, False, f"no answer within {timeout_s:g} s")
        if not out.confirmed:
            out.detail += f"; its watchdog stows it within {hb:g} s"
        outcomes.append(out)
    if state is not None:
        stowed = [o.tracker for o in outcomes if o.wanted == "stow" and o.ours]
        left = [o.tracker for o in outcomes if not o.ours]
        try:
            record = {"time": time.time(), "stowed": stowed, "left": left}
            atomic_write(state.shutdown, json.dumps(record) + "\n")
        except OSError as exc:
            log.warning(
                "%s: not written (%s): the next start leaves these drives stowed", state.shutdown, exc
            )
    return outcomes
