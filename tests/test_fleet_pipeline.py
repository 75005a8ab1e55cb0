"""A mission of two vehicles of different types as processes: the launcher starts helm, pid and
sim per vehicle under one clock and logger, and the run equals `run_inprocess` bit for bit, the
checks between the vehicles (a close call, then a collision that ends it) included."""

import pytest
from test_fleet import TWO
from test_reliability import run_budget

from conftest import nearsub
from helpers import finish, log_path, per_topic, wait_paused, wait_registered
from nearsub.common.mission.cores import EncounterCheck, HelmCore, build_fleet, run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.lifecycle import run_inprocess
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
    # The summary's closest approaches (common/analysis/approach.py, from the log): the pair that
    # collided, touching at the end; no hull without a submarine.
    approaches = summary["approaches"]
    assert approaches["hull"] == {}
    assert approaches["closest_pair"]["vehicles"] == ["auv1", "auv2"]
    assert approaches["closest_pair"]["clearance_m"] <= 0.0
    assert approaches["closest_pair"]["t"] == pytest.approx(summary["sim_time"], abs=mission.dt)


def test_swap_names_the_vehicle_and_replaces_only_its_helm(launches, community):
    """Paused before step 100, auv2's helm is swapped (with a setting of its own); auv1's runs
    on. The run equals run_inprocess with the same swap, no step skipped or repeated."""
    settings = [f"name={community}", "pause_at_step=100", "time_limit=40"]
    mission = load_mission(TWO, settings)
    process = launches.start(TWO, *(a for s in settings for a in ("--set", s)))
    wait_registered(community, timeout=3 * mission.startup_timeout)
    wait_paused(community, timeout=mission.startup_timeout + 100 * mission.step_timeout)
    missing = nearsub("swap", community, "helm", "--with", "max_speed=1.0")
    assert missing.returncode == 2 and "several vehicles (auv1, auv2): name one" in missing.stderr
    unknown = nearsub("swap", community, "helm", "--vehicle", "auv9")
    assert unknown.returncode == 2 and "no vehicle named 'auv9'" in unknown.stderr
    swapped = nearsub("swap", community, "helm", "--vehicle", "auv2", "--with", "max_speed=1.0", timeout=300)
    assert swapped.returncode == 0, swapped.stderr
    assert "swapped auv2/helm-1 -> auv2/helm-2 at step 100" in swapped.stdout
    code, summary, err = finish(process, timeout=run_budget(mission))
    assert code == 0 and summary["outcome"] == "time_limit", err

    after = load_mission(TWO, [*settings, "vehicles.auv2.apps.helm.max_speed=1.0"])
    swaps = {100: {"auv2/helm": HelmCore(after.member("auv2"))}}
    reference = run_inprocess(
        build_fleet(mission), mission.lockstep(), mission.dt, mission.max_steps, swaps, (), EncounterCheck(mission)
    )
    logged = per_topic(log_path(summary))
    for vehicle in ("auv1", "auv2"):
        for leaf in ("state", "desired"):
            assert logged[f"{vehicle}/{leaf}"] == [encode(m) for m in reference.topic(leaf, vehicle)], (vehicle, leaf)
    assert summary["swaps"] == [{"old": "auv2/helm-1", "new": "auv2/helm-2", "step": 100}]
    assert {"auv1/helm-1", "auv2/helm-2"} <= set(summary["cpu"])  # helm-1 retired
