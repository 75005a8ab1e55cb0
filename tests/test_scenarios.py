"""The chapter 5 and 6 scenario missions: their outcomes against the thesis, in-process, and the
runtime swap to N_uv compensation through the multi-process launcher."""

import pytest

from conftest import ROOT, nearsub
from helpers import finish, log_path, per_topic, wait_registered
from nearsub.common.analysis.scenarios import scenario_figures
from nearsub.common.mission.cores import HelmCore, build_cores, run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.lifecycle import Schedule, run_inprocess
from nearsub.common.runtime.messages import encode
from nearsub.common.surrogate.model import load_surrogate

pytestmark = pytest.mark.timeout(240)
MISSIONS = ROOT / "missions"


def figures(name, overrides=()):
    mission = load_mission(MISSIONS / f"{name}.toml", list(overrides))
    return scenario_figures(mission, run_mission(mission))


def test_large_uuv_collides_near_the_stern_with_the_standard_waypoints():
    """Figure 5-5."""
    result = figures("overtake_stern_standard")
    assert result.outcome == "collision" and result.closest_approach <= 0.0
    assert result.closest_at[0] < -20.0  # aft of the CB, where the stern pulls the UUV in


def test_nuv_compensation_avoids_the_stern_collision():
    """Figure 6-2 (b): the same overtake with N_uv compensation ends without a collision."""
    result = figures("overtake_stern_nuv")
    assert result.outcome == "completed" and result.waypoints_reached == 1
    assert result.closest_approach > 0.0


def test_modified_waypoints_stay_on_the_octagon_where_the_standard_ones_stray():
    """Figure 6-6: the standard behaviour is pushed far off the legs that cross the flow."""
    standard, modified = figures("octagon_standard"), figures("octagon_modified")
    assert standard.max_cross_track > 5.0 and standard.stray_fraction > 0.5
    assert modified.waypoints_reached == 8 and modified.outcome == "completed"
    assert modified.max_cross_track <= 2.0  # the capture radius: the offset at a leg switch
    assert modified.stray_fraction < 0.2


def test_lateral_approach_strays_only_across_the_flow():
    """Figure 6-3: on track along the submarine, pushed off the track-line across the flow."""
    result = figures("lateral_approach")
    along, across = result.max_cross_track_per_waypoint[:2]
    assert along <= 1.0 < across


def test_a_swap_between_the_same_cores_in_process_changes_nothing():
    """run_inprocess's swap hands the progress over: an identical helm changes no message."""
    mission = load_mission(MISSIONS / "alpha.toml", ["time_limit=30"])
    plain = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    swapped = run_inprocess(
        build_cores(mission),
        Schedule(mission.periods()),
        mission.dt,
        mission.max_steps,
        {300: {"helm": HelmCore(mission)}},
    )
    assert [encode(m) for _, _, m in swapped.messages] == [encode(m) for _, _, m in plain.messages]


SWAP_STEP = 200  # 10 s into the overtake, 12 m behind the stern tip (every swap up to step 2400 survives)


def test_swapping_in_nuv_compensation_mid_run_avoids_the_collision(launches, community):
    """Issue 7 item 4 at warp 0: the overtake starts with the standard helm and the compensating
    helm is swapped in at a fixed step. The log equals the in-process run with the same swap."""
    mission_file = MISSIONS / "overtake_stern_standard.toml"
    process = launches.start(mission_file, "--set", f"name={community}", "--set", f"pause_at_step={SWAP_STEP}")
    wait_registered(community, timeout=2 * load_mission(mission_file).startup_timeout)  # the server, then the apps
    swap = nearsub("swap", community, "helm", "--at-step", str(SWAP_STEP), "--behaviour", "nuv_compensation", "--json")
    assert swap.returncode == 0, swap.stderr
    code, summary, err = finish(process, timeout=200)
    assert code == 0, err
    assert summary["outcome"] == "completed", summary

    surrogate = load_surrogate(None)
    mission = load_mission(mission_file, [f"name={community}"])
    compensating = load_mission(mission_file, [f"name={community}", "apps.helm.behaviour=nuv_compensation"])
    reference = run_inprocess(
        build_cores(mission, surrogate),
        Schedule(mission.periods()),
        mission.dt,
        mission.max_steps,
        {SWAP_STEP: {"helm": HelmCore(compensating, surrogate)}},
    )
    assert reference.outcome == "completed"
    logged = per_topic(log_path(summary))
    for leaf in ("state", "desired", "input", "forces"):
        assert logged[f"sdv/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf
