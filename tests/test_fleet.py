"""Several vehicles in one mission: the `[[vehicles]]` schema, `--set vehicles.NAME...`, the
in-process fleet (its lock-step, its end, the checks between vehicles) and the capsule geometry."""

import math

import numpy as np
import pytest

from conftest import ROOT
from nearsub.common.mission.cores import EncounterCheck, run_mission
from nearsub.common.mission.schema import MissionError, load_mission, mission_from_dict
from nearsub.common.physics import encounters
from nearsub.common.physics.hull import explorer_radius
from nearsub.common.physics.vehicles import LIBRARY
from nearsub.common.runtime.messages import State

TWO = ROOT / "tests" / "data" / "fleet-two.toml"


def test_vehicles_merge_their_apps_over_the_missions_key_by_key():
    mission = load_mission(TWO)
    auv1, auv2 = mission.members()
    assert [auv1.vehicle_name, auv2.vehicle_name] == ["auv1", "auv2"] == mission.vehicle_names
    assert (auv1.vehicle_model.name, auv2.vehicle_model.name) == ("remus100", "sdv")
    assert auv1.apps.helm.period == 5 and auv2.apps.helm.period == 10  # auv2's own setting
    assert auv1.apps.helm.legs == mission.apps.helm.legs  # the shared legs
    assert [leg.points for leg in auv2.apps.helm.legs] == [[(60.0, 30.0)]]  # a list is replaced, not appended
    assert auv2.apps.pid == auv1.apps.pid == mission.apps.pid
    assert (auv1.start.y, auv2.start.y) == (0.0, 20.0)
    # A dump validates again to the same mission (the merge is idempotent): what apps receive.
    assert mission_from_dict(mission.model_dump(mode="json")) == mission
    with pytest.raises(ValueError, match="several vehicles"):
        _ = mission.vehicle_name


@pytest.mark.parametrize(
    "override, expected",
    [
        (
            "vehicles.auv3.start.y=1",
            "--set vehicles.auv3.start.y=1: no vehicle named 'auv3' (the mission's vehicles: auv1, auv2)",
        ),
        ("vehicles.auv2.type='torpedo'", "field 'vehicles.auv2.type' = 'torpedo'"),
        (
            "vehicles.auv2.name='auv1'",
            "field 'vehicles' = ['auv1', 'auv1']: Value error, vehicle name 'auv1' is given twice",
        ),
        ("vehicles.auv2.colour='red'", "field 'vehicles.auv2.colour' = 'red': Extra inputs"),
        ("vehicles.auv2.name='a/b'", "field 'vehicles.a/b.name' = 'a/b'"),
        ("vehicles.auv2.name='clock'", "field 'vehicles.clock.name' = 'clock': Value error, 'clock' is a mission-wide"),
        ("vehicles.auv2.apps.helm.period=0", "field 'vehicles.auv2.apps.helm.period' = 0"),
        ("vehicles.auv2.apps.logger.enabled=false", "field 'vehicles.auv2.apps.logger' "),
        ("vehicle='sdv'", "give each vehicle its type and start in its entry, not the mission's vehicle = 'sdv'"),
    ],
)
def test_bad_vehicle_entries_are_one_line_naming_the_field_and_value(override, expected):
    with pytest.raises(MissionError) as info:
        load_mission(TWO, [override])
    message = str(info.value)
    assert expected in message and "\n" not in message, message


def test_set_reaches_one_vehicle():
    mission = load_mission(TWO, ["vehicles.auv2.start.y=12", "vehicles.auv1.apps.pid.form='incremental'"])
    auv1, auv2 = mission.members()
    assert auv2.start.y == 12.0 and auv1.start.y == 0.0
    assert auv1.apps.pid.form == "incremental" and auv2.apps.pid.form == "positional"


def test_a_vehicle_without_a_helm_form_is_refused(tmp_path):
    text = TWO.read_text().replace("[[apps.helm.legs]]\npoints = [[60.0, 0.0]]\nspeed = 1.5\n", "")
    path = tmp_path / "bare.toml"
    path.write_text(text)
    with pytest.raises(MissionError, match="vehicles.auv1.apps.helm' .*give the waypoint legs"):
        load_mission(path)


def test_fleet_in_process_completes_when_every_vehicle_has_and_keeps_the_first_one_going():
    mission = load_mission(TWO)
    result = run_mission(mission)
    assert result.outcome == "completed", result.reason
    assert "every vehicle completed" in result.reason
    completion = {}
    for vehicle in ("auv1", "auv2"):
        helm = result.topic("helm", vehicle)
        completion[vehicle] = next(m.step for m in helm if m.complete)
        # Every vehicle's apps ran every step to the end, under its own period.
        assert result.topic("state", vehicle)[-1].step == result.steps
        assert len(result.topic("input", vehicle)) == result.steps
    assert result.topic("helm", "auv2")[1].step - result.topic("helm", "auv2")[0].step == 10
    # The SDV, slower to turn and farther, completes last: the mission ends with it.
    assert completion["auv1"] < completion["auv2"] <= result.steps - 1
    assert not result.topic("events")  # far apart: no encounter


def test_a_collision_between_two_vehicles_ends_the_mission_with_a_close_call_first():
    # Both head for the same point: the SDV reaches the REMUS 100 that waits there.
    mission = load_mission(TWO, ["vehicles.auv2.apps.helm.legs=[{points=[[60.0, 0.0]], speed=1.5}]", "time_limit=120"])
    result = run_mission(mission)
    assert result.outcome == "collision" and "between auv1 and auv2" in result.reason
    kinds = [e.kind for e in result.topic("events")]
    assert kinds == ["close_call", "collision"]
    collision = result.topic("events")[-1]
    assert collision.source == "encounters" and collision.data["clearance"] <= 0
    assert collision.step == result.steps  # found at x_{k+1}; every app stopped after step k
    for vehicle in ("auv1", "auv2"):
        assert result.topic("state", vehicle)[-1].step == result.steps


def test_one_vehicle_of_a_fleet_flies_like_the_same_single_vehicle_mission():
    alone = load_mission(TWO, ["vehicles=[{name='auv1', type='remus100'}]"])
    single = mission_from_dict(
        {**{k: v for k, v in alone.model_dump(mode="json").items() if k != "vehicles"}, "vehicle": "remus100"}
    )
    a, b = run_mission(alone), run_mission(single)
    assert (a.outcome, a.steps) == (b.outcome, b.steps)
    assert a.topic("state", "auv1") == b.topic("state")


def test_capsules_contain_the_explorer_profile():
    for vehicle in LIBRARY.values():
        capsule = encounters.Capsule.of(vehicle.length, vehicle.diameter)
        nose = capsule.ahead + capsule.radius  # CB to nose
        s = np.linspace(0.0, vehicle.length, 4001)
        axial = nose - s  # body x of each profile station
        beyond = np.clip(np.maximum(axial - capsule.ahead, -capsule.behind - axial), 0.0, None)
        width = np.sqrt(np.clip(capsule.radius**2 - beyond**2, 0.0, None))
        assert np.all(explorer_radius(s, vehicle.length, vehicle.diameter) <= width + 1e-12), vehicle.name
        assert math.isclose(capsule.ahead + capsule.behind + 2 * capsule.radius, vehicle.length)


def test_clearance_between_capsules():
    remus = LIBRARY["remus100"]
    c = encounters.Capsule.of(remus.length, remus.diameter)
    # Side by side and parallel: the distance between the axes minus one diameter.
    assert math.isclose(encounters.clearance(c, (0, 0, 0), c, (0, 1.0, 0)), 1.0 - remus.diameter)
    # Nose to tail on one line: the gap between the nose of one and the tail of the other.
    gap = encounters.clearance(c, (0, 0, 0), c, (remus.length + 0.3, 0, 0))
    assert math.isclose(gap, 0.3, abs_tol=1e-12)
    # Crossing: a collision; parallel and far apart: neither.
    assert encounters.classify_pair(c, (0, 0, 0), c, (0, 0, math.pi / 2)).collision
    far = encounters.classify_pair(c, (0, 0, 0), c, (0, 5.0, 0))
    assert not far.collision and not far.close_call
    near = encounters.classify_pair(c, (0, 0, 0), c, (0, remus.diameter * 1.5, 0))
    assert near.close_call and not near.collision


def test_the_encounter_check_reports_a_close_call_once_per_entry():
    check = EncounterCheck(load_mission(TWO))

    def states(y2: float) -> dict:
        return {
            "auv1": State(step=1, t=0.05, source="sim", u=1, v=0, r=0, x=0, y=0, psi=0),
            "auv2": State(step=1, t=0.05, source="sim", u=1, v=0, r=0, x=0, y=y2, psi=0),
        }

    kinds = [[e.kind for e in check.observe(k, states(y)).events] for k, y in enumerate((5, 0.7, 0.7, 5, 0.7))]
    assert kinds == [[], ["close_call"], [], [], ["close_call"]]
    assert check.observe(5, states(0.3)).end == "collision"


def test_launch_two_departs_in_order_clear_of_the_hull_and_of_each_other():
    """missions/launch_two.toml (docs/scenarios/launch_two.md), in-process."""
    from nearsub.common.analysis.fleet import fleet_figures

    mission = load_mission(ROOT / "missions" / "launch_two.toml")
    assert mission_from_dict(mission.model_dump(mode="json")) == mission
    behaviours = [spec.name for spec in mission.member("auv2").apps.helm.behaviours]
    assert behaviours == ["avoid_hull", "op_region", "pace_heading", "pace_speed", "hold", "wait", "depart"]
    result = run_mission(mission)
    figures = fleet_figures(mission, result)
    assert result.outcome == "completed", result.reason
    auv1, auv2 = figures.vehicle("auv1"), figures.vehicle("auv2")
    # Both depart and complete; auv2 starts only once auv1 has reached its departure point.
    assert auv1.completed_at is not None and auv2.completed_at is not None
    assert auv1.phase_times["depart"] < auv1.phase_times["clear"] < auv2.phase_times["depart"]
    kinds = {e.kind for _, leaf, e in result.messages if leaf == "events"}
    assert not kinds & {"collision", "close_call", "error"}, kinds
    # Clear of the hull (a close call is one diameter: 0.19 m and 0.42 m) and of each other.
    assert auv1.closest_hull > 1.0 and auv2.closest_hull > 1.0
    gap, _ = figures.closest_pair[("auv1", "auv2")]
    assert gap > 10.0
    # Each held its station within 0.2 m until it departed.
    for v, point in ((auv1, (8.0, 6.5)), (auv2, (-14.0, 7.0))):
        holding = v.times < v.phase_times["depart"]
        assert np.max(np.hypot(v.track[holding, 0] - point[0], v.track[holding, 1] - point[1])) < 0.2


def test_launch_four_departs_in_its_plan_clear_of_the_hull_and_of_each_other():
    """missions/launch_four.toml (docs/scenarios/launch_four.md), in-process: four UUVs, launch_two's
    pair and a second one forward and aft of it."""
    from nearsub.common.analysis.fleet import fleet_figures

    mission = load_mission(ROOT / "missions" / "launch_four.toml")
    result = run_mission(mission)
    figures = fleet_figures(mission, result)
    assert result.outcome == "completed", result.reason
    assert [v.name for v in figures.vehicles] == ["auv1", "auv2", "auv3", "auv4"]
    assert all(v.completed_at is not None for v in figures.vehicles)
    auv1, auv2, auv3, auv4 = figures.vehicles
    # The plan: the forward pair first, the aft pair once both of it have reached their departure points.
    departs = [v.phase_times["depart"] for v in (auv1, auv3, auv2, auv4)]
    assert departs == sorted(departs)
    assert max(auv1.phase_times["clear"], auv3.phase_times["clear"]) < auv2.phase_times["depart"]
    kinds = {e.kind for _, leaf, e in result.messages if leaf == "events"}
    assert not kinds & {"collision", "close_call", "error"}, kinds
    # Clear of the hull (a close call is one diameter: 0.19 m and 0.42 m) and of each other.
    assert all(v.closest_hull > 1.0 for v in figures.vehicles), [v.closest_hull for v in figures.vehicles]
    assert len(figures.closest_pair) == 6
    assert all(gap > 5.0 for gap, _ in figures.closest_pair.values()), figures.closest_pair
    # Each stayed within its station_keep's tolerance until it departed.
    for v in figures.vehicles:
        hold = next(s for s in mission.member(v.name).apps.helm.behaviour_specs() if s.name == "hold")
        holding = v.times < v.phase_times["depart"]
        off = np.hypot(v.track[holding, 0] - hold.point[0], v.track[holding, 1] - hold.point[1])
        assert np.max(off) < hold.tolerance, (v.name, np.max(off))
