"""A mission of two vehicles of different types as processes: the launcher starts helm, pid and
sim per vehicle under one clock and logger, and the run equals `run_inprocess` bit for bit, the
checks between the vehicles (a close call, then a collision that ends it) included."""

import pytest
from test_fleet import TWO
from test_reliability import run_budget

from helpers import log_path, per_topic
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.messages import encode

pytestmark = pytest.mark.timeout(600)

# auv2 (an SDV) heads for the point where auv1 (a REMUS 100) waits after its waypoint.
MEET = "vehicles.auv2.apps.helm.legs=[{points=[[60.0, 0.0]], speed=1.5}]"


def test_two_vehicles_as_processes_equal_in_process_bit_for_bit(launches, community):
    mission = load_mission(TWO, [f"name={community}", MEET])
    code, summary, err = launches.run(TWO, "--set", f"name={community}", "--set", MEET, timeout=run_budget(mission))
    assert code == 0, err
    reference = run_mission(mission)
    assert (summary["outcome"], summary["steps"]) == (reference.outcome, reference.steps)
    assert reference.outcome == "collision"
    assert "between auv1 and auv2" in summary["reason"]
    logged = per_topic(log_path(summary))
    for vehicle in ("auv1", "auv2"):
        for leaf in ("state", "desired", "input", "helm"):
            expected = [encode(m) for m in reference.topic(leaf, vehicle)]
            assert logged[f"{vehicle}/{leaf}"] == expected, (vehicle, leaf)
    encounters = [encode(m) for m in reference.topic("events")]
    assert logged["events/encounters"] == encounters and len(encounters) == 2
    # Processes are named per vehicle; only the clock checks between vehicles.
    assert {"auv1/helm-1", "auv1/pid-1", "auv1/sim-1", "auv2/helm-1", "auv2/pid-1", "auv2/sim-1"} <= set(summary["cpu"])
    assert summary["vehicles"]["auv1"]["waypoints_reached"] == 1
    assert summary["vehicles"]["auv2"]["waypoints_reached"] == 0
    assert summary["events"]["collision"] == 1 and summary["events"]["close_call"] == 1
