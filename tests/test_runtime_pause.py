"""A running mission paused for longer than its step timeout resumes and ends as if never paused."""

import time

import pytest
from test_live import wait_paused

from conftest import ALPHA, nearsub
from helpers import finish, log_path, per_topic, wait_registered
from nearsub.common.mission.cores import build_cores
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.lifecycle import Schedule, run_inprocess
from nearsub.common.runtime.messages import encode

pytestmark = pytest.mark.timeout(1500)  # above the sum of the bounds below


def test_a_pause_longer_than_the_step_timeout_then_resume(launches, community):
    overrides = [f"name={community}", "step_timeout=3", "pause_at_step=200", "time_limit=20"]
    mission = load_mission(ALPHA, overrides)
    process = launches.start(ALPHA, *(arg for item in overrides for arg in ("--set", item)))
    assert mission.warp == 0  # the pause comes as soon as the apps have run 200 steps
    # the launcher starts its router, then gives the logger and the apps startup_timeout each
    wait_registered(community, timeout=3 * mission.startup_timeout)
    # each step within step_timeout, or the clock ends the mission as stalled
    status = wait_paused(community, timeout=200 * mission.step_timeout)
    assert (status["step"], status["paused"]) == (200, True)
    time.sleep(2 * mission.step_timeout)
    assert process.poll() is None
    resumed = nearsub("clock", community, "resume")
    assert resumed.returncode == 0, resumed.stderr
    code, summary, err = finish(process, timeout=200 * mission.step_timeout)  # 200 steps to go
    assert code == 0, err
    assert summary["outcome"] == "time_limit" and summary["steps"] == 400, summary

    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    logged = per_topic(log_path(summary))
    for leaf in ("state", "desired", "input"):
        assert logged[f"remus100/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf
