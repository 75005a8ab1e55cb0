"""Ctrl-C while a launch starts up: whenever it comes (the router started, the first app forked,
the lock-stepped apps forked), the launch ends with one line, exit code 130, no traceback from
any process, and nothing of it left running. The points are the launcher's own progress lines, so
the test keeps its order on a loaded machine. And the launcher's policy once interrupted: an
interrupt wins over a normal end it drains after it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading

import pytest

from conftest import ROOT
from helpers import STARTUP_TIMEOUT, processes_under, wait_until
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Mail
from nearsub.common.runtime.messages import MissionEnd, encode
from nearsub.tools.launcher.status import exit_code
from nearsub.tools.launcher.supervision import Launcher

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


INTERRUPTED = MissionEnd(step=40, t=2.0, source="launcher", outcome="interrupted", reason="stopped by the user")
NORMAL = MissionEnd(step=41, t=2.05, source="clock", outcome="time_limit", reason="time limit reached")


@pytest.mark.parametrize(
    "ends, outcome",
    [([NORMAL], "time_limit"), ([INTERRUPTED, NORMAL], "interrupted"), ([NORMAL, INTERRUPTED], "interrupted")],
    ids=["normal", "interrupt-first", "clock-first"],
)
def test_an_interrupt_wins_over_a_normal_end_in_the_mailbox(tmp_path, ends, outcome):
    """After Ctrl-C the launcher drains its mailbox, where the clock's normal end may lie beside
    the launcher's own interrupted one, in either order: the launch stays interrupted (exit 130)."""
    launcher = Launcher(load_mission(ROOT / "missions" / "alpha.toml", []), None, str(tmp_path), quiet=True)
    for end in ends:
        assert launcher.handle(Mail("sample", keys.mission_end(launcher.community), encode(end)))
    summary = launcher.summary
    assert summary.outcome == outcome and exit_code(summary) == (130 if outcome == "interrupted" else 0)
    assert summary.steps == ends[-1].step  # the step is the last end's
