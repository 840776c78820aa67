"""One ``heliotrack run`` per state folder: a second one on the same ``--state`` would drive
the same drives and overwrite the first's records; it is refused in one line naming the
first's pid (an audit's finding: both ran and fought over the drives)."""

from __future__ import annotations

import signal

import pytest

from controller.errors import UserError
from heliotrack.cli import main
from hil.pty import PtyLink
from tests.heliotrack.plant_emulators import heliotrack
from tests.heliotrack.test_run_faults import _silent_plant


def test_a_second_run_on_the_same_state_folder_is_refused(tmp_path, capsys):
    state = tmp_path / "state"
    with PtyLink.open() as link:
        cfg = _silent_plant(tmp_path, link.path)
        first = heliotrack("run", "--config", str(cfg), "--state", str(state))
        try:
            assert "heliotrack run:" in first.stderr.readline()  # started: the folder is its
            assert main(["run", "--config", str(cfg), "--state", str(state), "--duration", "1"]) == 2
            err = capsys.readouterr().err.strip()
            assert err == (
                f"heliotrack: error: --state {state}: in use by another heliotrack run (pid {first.pid})"
            ), err
            assert first.poll() is None  # the first one is left alone
            first.send_signal(signal.SIGTERM)
            assert first.wait(10) == 0
        finally:
            if first.poll() is None:
                first.kill()
        # the first one gone, the folder is free again (the lock file stays, unlocked)
        assert main(["run", "--config", str(cfg), "--state", str(state), "--duration", "1"]) == 0
    assert (state / ".lock").exists()


def test_the_lock_goes_with_the_process_not_the_file(tmp_path):
    """A lock file left by a killed run (a pid in it, nobody holding it) does not block."""
    from heliotrack.runtime import StateFolder, claim_state_folder

    state = StateFolder(tmp_path)
    state.lock.write_text("999999\n")
    with claim_state_folder(state):
        with pytest.raises(UserError, match=r"in use by another heliotrack run \(pid \d+\)"):
            with claim_state_folder(state):
                pass
    with claim_state_folder(state):
        pass
    with claim_state_folder(None):  # no --state: nothing to claim
        pass
