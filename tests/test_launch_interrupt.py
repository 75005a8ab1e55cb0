"""Ctrl-C while a launch starts up: whenever it comes (the router started, the first app forked,
the lock-stepped apps forked), the launch ends with one line, exit code 130, no traceback from
any process, and nothing of it left running. The points are the launcher's own progress lines, so
the test keeps its order on a loaded machine."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading

import pytest

from conftest import ROOT
from helpers import STARTUP_TIMEOUT, processes_under, wait_until

MISSION = ROOT / "missions" / "overtake_stern_nuv.toml"  # near the submarine: the surrogate server too
STOP_LADDER = 2 * 5.0  # SIGINT, then SIGTERM, then SIGKILL, 5 s apart (tools/launcher)

pytestmark = pytest.mark.timeout(6 * STARTUP_TIMEOUT)


@pytest.mark.parametrize("progress", ["started router", "started logger", "started sim-1"])
def test_ctrl_c_during_start_up_is_one_line_and_exit_130(launches, community, progress):
    argv = [sys.executable, "-m", "nearsub", "launch", str(MISSION), "--log", str(launches.log_dir)]
    process = subprocess.Popen(
        [*argv, "--set", f"name={community}"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        process_group=0,  # its own group, which Ctrl-C on a terminal signals as a whole
    )
    launches.processes.append(process)
    said: list[str] = []
    reached = threading.Event()

    def read_progress() -> None:
        for line in process.stderr:
            said.append(line)
            if progress in line:
                os.killpg(process.pid, signal.SIGINT)
                reached.set()

    reader = threading.Thread(target=read_progress, daemon=True)
    reader.start()
    wait_until(reached.is_set, STARTUP_TIMEOUT, f"the launch did not say {progress!r}")
    out = process.stdout.read()
    process.wait(timeout=STARTUP_TIMEOUT + STOP_LADDER)
    reader.join(timeout=STARTUP_TIMEOUT)
    err = "".join(said)
    assert process.returncode == 130, (out, err)
    assert out == f"mission {community}: interrupted (stopped by the user during start-up)\n", (out, err)
    assert "Traceback" not in err and "Error" not in err, err
    assert all(line.startswith("[launch") for line in said), err  # only its progress lines
    for output in launches.log_dir.rglob("*.out"):  # no app printed a traceback either
        assert "Traceback" not in output.read_text(), output
    wait_until(lambda: not processes_under(launches.log_dir), STARTUP_TIMEOUT, "processes of the launch left")
