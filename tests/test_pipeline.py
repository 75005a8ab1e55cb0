"""The multi-process mission: complete, deterministic, warp-independent, equal to in-process."""

import uuid

import pytest
from test_reliability import run_budget

from conftest import ALPHA, Launches
from helpers import log_path, per_topic
from nearsub.common.mission.cores import build_cores
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.lifecycle import Schedule, run_inprocess
from nearsub.common.runtime.logfile import read_log
from nearsub.common.runtime.messages import encode

pytestmark = pytest.mark.timeout(300)  # a hang guard, above BUDGET


def test_alpha_mission_completes_every_waypoint(launches, community):
    code, summary, err = launches.run(ALPHA, "--set", f"name={community}", timeout=150)
    assert code == 0, err
    assert summary["outcome"] == "completed"
    assert summary["waypoints_reached"] == 6
    contents = read_log(log_path(summary))
    assert not contents.recovered
    assert contents.metadata["outcome"]["outcome"] == "completed"


BUDGET = run_budget(load_mission(ALPHA, ["time_limit=60"]))  # wall seconds a launch of the first minute may take


@pytest.fixture(scope="module")
def first_minute(tmp_path_factory):
    """The summary of one warp-0 launch of alpha's first 60 s, shared by the checks below."""
    tmp = tmp_path_factory.mktemp("pipeline")
    (tmp / "runtime").mkdir()
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("NEARSUB_RUNTIME_DIR", str(tmp / "runtime"))
        handle = Launches(tmp / "logs")
        try:
            code, summary, err = handle.run(
                ALPHA, "--set", f"name=t{uuid.uuid4().hex[:10]}", "--until", "60", timeout=BUDGET
            )
        finally:
            handle.kill_all()
    assert code == 0 and summary["outcome"] == "time_limit", err
    return summary


def test_two_runs_log_identical_contents(first_minute, launches, community):
    code, summary, err = launches.run(ALPHA, "--set", f"name={community}", "--until", "60", timeout=BUDGET)
    assert code == 0, err
    first, second = per_topic(log_path(first_minute)), per_topic(log_path(summary))
    assert first.keys() == second.keys()
    for topic in first:
        assert first[topic] == second[topic], topic
    assert len(first["remus100/state"]) == 60 / 0.05 + 1


def test_warp_zero_and_warp_twenty_give_identical_logs(first_minute, launches, community):
    _, paced, err = launches.run(ALPHA, "--set", f"name={community}", "--until", "60", "--warp", "20", timeout=BUDGET)
    assert paced["outcome"] == "time_limit", err
    assert paced["run_wall_time"] >= 60 / 20 * 0.95  # it really was paced
    a, b = per_topic(log_path(first_minute)), per_topic(log_path(paced))
    for topic in a:
        assert a[topic] == b[topic], topic


def test_multi_process_equals_in_process_bit_for_bit(first_minute):
    mission = load_mission(ALPHA, [f"name={first_minute['community']}", "time_limit=60"])
    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    logged = per_topic(log_path(first_minute))
    for leaf in ("state", "desired", "input", "helm"):
        assert logged[f"remus100/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf
