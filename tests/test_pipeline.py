"""The multi-process mission: complete, deterministic, warp-independent, equal to in-process."""

import pytest

from conftest import ALPHA
from helpers import log_path, per_topic
from nearsub.common.mission.cores import build_cores
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.lifecycle import Schedule, run_inprocess
from nearsub.common.runtime.logfile import read_log
from nearsub.common.runtime.messages import encode

pytestmark = pytest.mark.timeout(180)


def test_alpha_mission_completes_every_waypoint(launches, community):
    code, summary, err = launches.run(ALPHA, "--set", f"name={community}", timeout=150)
    assert code == 0, err
    assert summary["outcome"] == "completed"
    assert summary["waypoints_reached"] == 6
    contents = read_log(log_path(summary))
    assert not contents.recovered
    assert contents.metadata["outcome"]["outcome"] == "completed"


def test_two_runs_log_identical_contents(launches, community):
    logs = []
    for run in range(2):
        code, summary, err = launches.run(ALPHA, "--set", f"name={community}{run}", "--until", "40")
        assert code == 0, err
        logs.append(per_topic(log_path(summary)))
    first, second = logs
    assert first.keys() == second.keys()
    for topic in first:
        assert first[topic] == second[topic], topic
    assert len(first["remus100/state"]) == 40 / 0.05 + 1


def test_warp_zero_and_warp_twenty_give_identical_logs(launches, community):
    _, fast, err = launches.run(ALPHA, "--set", f"name={community}a", "--until", "60", "--warp", "0")
    _, paced, err2 = launches.run(ALPHA, "--set", f"name={community}b", "--until", "60", "--warp", "20")
    assert fast["outcome"] == paced["outcome"] == "time_limit", err + err2
    assert paced["run_wall_time"] >= 60 / 20 * 0.95  # it really was paced
    a, b = per_topic(log_path(fast)), per_topic(log_path(paced))
    for topic in a:
        assert a[topic] == b[topic], topic


def test_multi_process_equals_in_process_bit_for_bit(launches, community):
    code, summary, err = launches.run(ALPHA, "--set", f"name={community}", "--until", "60")
    assert code == 0, err
    mission = load_mission(ALPHA, [f"name={community}", "time_limit=60"])
    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    logged = per_topic(log_path(summary))
    for leaf in ("state", "desired", "input", "helm"):
        assert logged[f"remus100/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf
