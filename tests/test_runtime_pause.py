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

pytestmark = pytest.mark.timeout(900)  # above the bound of the finish below


def test_a_pause_longer_than_the_step_timeout_then_resume(launches, community):
    overrides = [f"name={community}", "step_timeout=3", "pause_at_step=200", "time_limit=20"]
    mission = load_mission(ALPHA, overrides)
    process = launches.start(ALPHA, *(arg for item in overrides for arg in ("--set", item)))
    wait_registered(community, timeout=mission.startup_timeout)
    assert wait_paused(community, timeout=mission.startup_timeout) == {"step": 200, "paused": True}
    time.sleep(2 * mission.step_timeout)
    assert process.poll() is None
    resumed = nearsub("clock", community, "resume")
    assert resumed.returncode == 0, resumed.stderr
    # after the resume the apps have step_timeout per step, and 200 steps to go
    code, summary, err = finish(process, timeout=mission.startup_timeout + 200 * mission.step_timeout)
    assert code == 0, err
    assert summary["outcome"] == "time_limit" and summary["steps"] == 400, summary

    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    logged = per_topic(log_path(summary))
    for leaf in ("state", "desired", "input"):
        assert logged[f"remus100/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf
