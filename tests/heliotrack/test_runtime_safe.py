"""``go_safe`` at shutdown: a stow this controller did not command is left to its owner."""

import json

import pytest

from firmware_protocol import Command, Mode, encode, register
from heliotrack.runtime import StateFolder, go_safe, resume_last_shutdown


def command(fw, cmd):
    reg = register("COMMAND")
    fw.write(reg.address(), encode(reg, int(cmd)))


def test_a_stow_someone_else_set_is_left_and_not_resumed_by_the_next_start(default_plant, tmp_path):
    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    command(fws["row-1"], Command.STOW)  # a local wind switch / maintenance panel
    clock.sleep(cfg.control.period_s)
    recs = run(ctl.cycle())
    assert "left stowed" in recs[1].health_reason
    state = StateFolder(tmp_path)
    out = {o.tracker: o for o in run(go_safe(ctl, state=state))}
    assert out["row-1"].confirmed and not out["row-1"].ours and "not by us" in out["row-1"].detail
    assert out["dual-1"].ours and fws["dual-1"].modes[0] == Mode.STOW  # ours: stowed, recorded
    assert json.loads(state.shutdown.read_text())["stowed"] == ["dual-1"]
    # the next start resumes only the stow it commanded; the switch's stays
    assert resume_last_shutdown(ctl, state) == ["dual-1"]
    for _ in range(2):
        clock.sleep(cfg.control.period_s)
        recs = run(ctl.cycle())
    assert fws["dual-1"].modes[0] == Mode.AUTO and fws["row-1"].modes[0] == Mode.STOW
    assert "left stowed" in recs[1].health_reason


def test_a_stow_left_at_shutdown_stays_left_after_its_watchdog_fired(default_plant, tmp_path):
    """The controller away longer than the heartbeat timeout: the drive already in a local
    STOW says COMM_LOST but not WATCHDOG_STOW (the watchdog did not stow it); the next start
    must not take that stow for the watchdog's (it resumed it before)."""
    from firmware_protocol import Status

    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    command(fws["row-1"], Command.STOW)
    clock.sleep(cfg.control.period_s)
    run(ctl.cycle())
    state = StateFolder(tmp_path)
    run(go_safe(ctl, state=state))
    assert json.loads(state.shutdown.read_text())["left"] == ["row-1"]
    fw = fws["row-1"]
    clock.sleep(cfg.control.heartbeat_timeout_s + 1)
    fw.update()
    assert fw.modes[0] == Mode.STOW and fw.comm_lost and not fw.status(0) & Status.WATCHDOG_STOW
    tr = next(t for t in ctl.trackers if t.cfg.name == "row-1")
    tr.health = type(tr.health)()  # a new process: nothing known but the record
    tr.health.last_ok = float("-inf")
    resume_last_shutdown(ctl, state)
    for _ in range(2):
        clock.sleep(cfg.control.period_s)
        recs = run(ctl.cycle())
    assert fw.modes[0] == Mode.STOW and "left stowed" in recs[1].health_reason


def test_an_unreadable_shutdown_record_is_kept_aside_not_deleted(default_plant, tmp_path):
    run, ctl, fws, clock, cfg = default_plant
    state = StateFolder(tmp_path)
    state.shutdown.write_text('{"stowed": ["dual-1"')  # cut short by a power cut
    assert resume_last_shutdown(ctl, state) == []
    kept = [p for p in tmp_path.iterdir() if p.name.startswith("shutdown.json.unusable-")]
    assert len(kept) == 1 and kept[0].read_text() == '{"stowed": ["dual-1"' and not state.shutdown.exists()


def test_a_stow_seen_as_someone_elses_stays_theirs_at_shutdown_though_its_link_dropped(
    default_plant, tmp_path
):
    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    command(fws["row-1"], Command.STOW)
    clock.sleep(cfg.control.period_s)
    run(ctl.cycle())  # seen: someone else's stow
    fw = fws["row-1"]
    clock.sleep(cfg.control.heartbeat_timeout_s + 1)  # the controller stalled: COMM_LOST
    fw.update()
    assert fw.comm_lost
    state = StateFolder(tmp_path)
    out = {o.tracker: o for o in run(go_safe(ctl, state=state))}
    assert not out["row-1"].ours and json.loads(state.shutdown.read_text())["left"] == ["row-1"]


def test_a_stow_seen_as_someone_elses_stays_theirs_after_kill_9(default_plant, tmp_path):
    """No shutdown record (kill -9, a power cut): the record ``run`` keeps while it runs
    says whose stow it was, so the COMM_LOST of a watchdog that found the drive stowed does
    not make it the watchdog's (older firmware: no WATCHDOG_STOW)."""
    from firmware_protocol import Status
    from heliotrack.runtime import note_foreign_stows

    run, ctl, fws, clock, cfg = default_plant
    state = StateFolder(tmp_path)
    on_record = note_foreign_stows(ctl, state, None)
    assert json.loads(state.foreign_stows.read_text())["trackers"] == []
    run(ctl.cycle())
    command(fws["row-1"], Command.STOW)  # a local switch
    clock.sleep(cfg.control.period_s)
    run(ctl.cycle())
    on_record = note_foreign_stows(ctl, state, on_record)
    assert json.loads(state.foreign_stows.read_text())["trackers"] == ["row-1"]
    # kill -9: nothing more is written; the watchdog fires while the controller is away
    fw = fws["row-1"]
    clock.sleep(cfg.control.heartbeat_timeout_s + 1)
    fw.update()
    assert fw.modes[0] == Mode.STOW and fw.comm_lost and not fw.status(0) & Status.WATCHDOG_STOW
    for tr in ctl.trackers:  # a new process
        tr.health = type(tr.health)()
        tr.health.last_ok = float("-inf")
    assert not state.shutdown.exists() and resume_last_shutdown(ctl, state) == []
    on_record = None
    for _ in range(2):
        clock.sleep(cfg.control.period_s)
        recs = run(ctl.cycle())
        on_record = note_foreign_stows(ctl, state, on_record)
    assert fw.modes[0] == Mode.STOW and "left stowed" in recs[1].health_reason
    # the switch released: the record follows
    command(fw, Command.RESUME)
    for _ in range(2):
        clock.sleep(cfg.control.period_s)
        run(ctl.cycle())
        on_record = note_foreign_stows(ctl, state, on_record)
    assert fw.modes[0] != Mode.STOW and json.loads(state.foreign_stows.read_text())["trackers"] == []


def test_an_unreadable_record_of_foreign_stows_is_ignored_with_a_warning(default_plant, tmp_path, caplog):
    run, ctl, fws, clock, cfg = default_plant
    state = StateFolder(tmp_path)
    state.foreign_stows.write_text('{"trackers": ["row-1"')  # cut short
    assert resume_last_shutdown(ctl, state) == []
    assert not any(tr.health.foreign_stow for tr in ctl.trackers)
    assert "foreign-stows.json: unreadable" in caplog.text


DEEP = "[" * 100000 + "]" * 100000


@pytest.mark.parametrize(
    ("name", "text", "why"),
    [
        ("shutdown.json", DEEP, "nested too deeply"),
        ("shutdown.json", '{"stowed": "dual-1"}', "stowed: expected a list of tracker names, got str"),
        ("shutdown.json", '{"stowed": {"dual-1": 1}}', "stowed: expected a list of tracker names, got dict"),
        ("shutdown.json", '{"stowed": [], "left": "row-1"}', "left: expected a list of tracker names"),
        ("foreign-stows.json", DEEP, "nested too deeply"),
        ("foreign-stows.json", '{"trackers": "dual-1"}', "trackers: expected a list of tracker names"),
    ],
)
def test_a_state_record_that_cannot_be_used_is_kept_aside_and_named(
    default_plant, tmp_path, caplog, name, text, why
):
    """An audit's cases: deep nesting crashed every start (RecursionError); a string of
    names was read as its letters; a bad foreign-stows record was overwritten."""
    run, ctl, fws, clock, cfg = default_plant
    state = StateFolder(tmp_path)
    (tmp_path / name).write_text(text)
    assert resume_last_shutdown(ctl, state) == []
    assert f"{name}: unreadable" in caplog.text and why in caplog.text
    kept = [p for p in tmp_path.iterdir() if p.name.startswith(f"{name}.unusable-")]
    assert len(kept) == 1 and kept[0].read_text() == text and not (tmp_path / name).exists()


def test_a_looping_link_for_a_record_or_the_state_folder_is_named(default_plant, tmp_path, caplog):
    from controller.errors import ConfigError
    from heliotrack.runtime import use_state_folder

    run, ctl, fws, clock, cfg = default_plant
    (tmp_path / "shutdown.json").symlink_to(tmp_path / "shutdown.json")
    assert resume_last_shutdown(ctl, StateFolder(tmp_path)) == []
    assert "shutdown.json: unreadable" in caplog.text
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    with pytest.raises(ConfigError, match="--state: expected a usable folder path"):
        use_state_folder(cfg, loop)


def test_a_drive_reading_an_impossible_angle_is_stowed_not_held(default_plant, tmp_path, caplog):
    """An audit's case: 'holding at 360.00, 0.00 deg', the clamped reading of a drive that
    said 1e6 deg, slewed it to a limit at shutdown."""
    from dataclasses import replace

    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    tr = next(t for t in ctl.trackers if t.cfg.name == "dual-1")
    tr.cfg = replace(tr.cfg, safe_position="hold")
    fws["dual-1"].axes[0].encoder_offset = 100_000.0
    out = {o.tracker: o for o in run(go_safe(ctl, state=StateFolder(tmp_path)))}
    assert (
        out["dual-1"].wanted == "stow" and out["dual-1"].confirmed and "holding" not in out["dual-1"].detail
    )
    assert fws["dual-1"].modes[0] == Mode.STOW
    assert (
        "outside its travel [0, 360]" in caplog.text and "stowed at shutdown instead of held" in caplog.text
    )


def test_a_drive_in_maintenance_is_left_whatever_its_flags_say(default_plant, tmp_path):
    """An audit's case: MAINTENANCE with COMM_LOST stuck was commanded to STOW and recorded
    as ours."""
    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    fw = fws["dual-1"]
    for k in range(2):
        fw._set_mode(k, Mode.MAINTENANCE)
    fw.comm_lost = True
    state = StateFolder(tmp_path)
    out = {o.tracker: o for o in run(go_safe(ctl, state=state))}
    assert out["dual-1"].detail == "in MAINTENANCE: left so" and not out["dual-1"].ours
    assert fw.modes == [Mode.MAINTENANCE, Mode.MAINTENANCE]
    assert "dual-1" not in json.loads(state.shutdown.read_text())["stowed"]


def test_a_drive_whose_state_cannot_be_trusted_is_sent_stow_anyway(default_plant, tmp_path):
    """An audit's case: an undefined mode value made the state read fail, and no STOW was
    sent ('no answer: ... 7 is not a valid Mode'); the drive had answered."""
    from controller.drives.base import DriveCommError

    run, ctl, fws, clock, cfg = default_plant
    _reading_fails(
        run, ctl, DriveCommError("dual-1: implausible state from the drive: 7 is not a valid Mode")
    )
    out = {o.tracker: o for o in run(go_safe(ctl, state=StateFolder(tmp_path)))}
    assert out["dual-1"].detail.startswith("state unreadable (dual-1: implausible state")
    assert "STOW sent, not read back" in out["dual-1"].detail and not out["dual-1"].confirmed
    assert fws["dual-1"].modes[0] == Mode.STOW


def test_one_drives_unexpected_error_leaves_the_others_safe_and_the_record_written(default_plant, tmp_path):
    """An audit's case: one drive's exception outside the link's errors ended the shutdown:
    no other drive stowed, no shutdown record, the links left open."""
    run, ctl, fws, clock, cfg = default_plant
    _reading_fails(run, ctl, RuntimeError("a library's surprise"))
    state = StateFolder(tmp_path)
    out = {o.tracker: o for o in run(go_safe(ctl, state=state))}
    assert not out["dual-1"].confirmed
    assert out["dual-1"].detail.startswith("failed: RuntimeError: a library's surprise")
    others = [name for name in out if name != "dual-1"]
    assert others and all(out[name].confirmed for name in others)
    assert fws[others[0]].modes[0] == Mode.STOW and state.shutdown.exists()


def _reading_fails(run, ctl, exc: Exception) -> None:
    """After one cycle, dual-1's state reads raise ``exc``."""
    run(ctl.cycle())
    tr = next(t for t in ctl.trackers if t.cfg.name == "dual-1")

    async def fails():
        raise exc

    tr.drive.read_state = fails
