"""The MOOS bridge without MOOS: .moos parsing, the mapping of MOOS variables (frames, units,
actuators), MOOS time against the sim's steps, malformed inputs, and the MOOS sim's core flying
the mission's own SimCore (docs/moos.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nearsub.common.mission import cores
from nearsub.common.moos import bridge
from nearsub.common.moos.config import Datum, MoosConfigError, parse_moos, sim_config
from nearsub.common.moos.sim import MoosSim, sim_mission
from nearsub.common.physics.vehicles import get_vehicle
from nearsub.common.runtime.messages import Input

ALPHA = """
ServerHost = localhost
ServerPort = 9123
Community  = alpha
MOOSTimeWarp = 10
LatOrigin  = 43.825300   // Forest Lake
LongOrigin = -70.330400

ProcessConfig = ANTLER
{
  Run = MOOSDB @ NewConsole = false
}

ProcessConfig = nearsub_sim
{
  AppTick   = 20
  CommsTick = 20
  start_pos = x=0, y=-20, heading=180, speed=0
  vehicle   = remus100
}
"""


def config_of(block: str, globals_: str = ""):
    return sim_config(parse_moos(f"{globals_}\nProcessConfig = nearsub_sim\n{{\n{block}\n}}\n", "m.moos"))


def test_the_globals_and_the_block_of_a_moos_file():
    config = sim_config(parse_moos(ALPHA, "alpha.moos"))
    assert (config.host, config.port, config.community, config.time_warp) == ("localhost", 9123, "alpha", 10.0)
    assert config.datum == Datum(43.8253, -70.3304)
    assert (config.app_tick, config.comms_tick) == (20.0, 20.0)
    assert config.start == {"x": 0.0, "y": -20.0, "heading": 180.0, "speed": 0.0}
    mission = sim_mission(config)
    assert (mission.start.x, mission.start.y, mission.start.psi_deg) == (0.0, -20.0, -90.0)
    assert mission.vehicle_model.name == get_vehicle("remus100").name
    assert not mission.environment.submarine


@pytest.mark.parametrize(
    ("block", "named"),
    [
        ("  AppTick = fast", "m.moos:4: apptick = fast: not a number"),
        ("  AppTick = 500", "m.moos:4: apptick = 500: outside"),
        ("  start_pos = x=0, z=3", "m.moos:4: start_pos = x=0, z=3: 'z=3'"),
        ("  turn_rate = 95", "m.moos:4: turn_rate = 95: unknown parameter"),
        ("  submarine = yes", "m.moos:4: submarine = yes: expected true or false"),
        ("  just words", "m.moos:4: 'just words': expected KEY = VALUE"),
    ],
)
def test_a_bad_line_is_one_error_naming_the_file_the_line_and_its_text(block, named):
    with pytest.raises(MoosConfigError) as caught:
        config_of(block)
    assert str(caught.value).startswith(named)
    assert "\n" not in str(caught.value)


def test_a_block_that_is_missing_or_not_closed_is_an_error():
    with pytest.raises(MoosConfigError, match="no ProcessConfig = nearsub_sim block"):
        sim_config(parse_moos("ServerPort = 9000\n", "m.moos"))
    with pytest.raises(MoosConfigError, match="not closed"):
        parse_moos("ProcessConfig = nearsub_sim\n{\n AppTick = 4\n", "m.moos")


def test_a_bad_mission_value_names_the_field():
    from nearsub.common.mission.schema import MissionError

    with pytest.raises(MissionError, match="vehicle"):
        sim_mission(config_of("  vehicle = kayak"))


@pytest.mark.parametrize(("psi_deg", "heading"), [(0, 90), (90, 0), (180, 270), (-90, 180), (45, 45), (-135, 225)])
def test_compass_headings_are_clockwise_from_north(psi_deg, heading):
    assert bridge.compass_heading(math.radians(psi_deg)) == pytest.approx(heading)
    assert math.degrees(bridge.psi_of_heading(heading)) % 360 == pytest.approx(psi_deg % 360)


@pytest.mark.parametrize(("heading", "yaw_deg"), [(0, 0), (90, -90), (180, 180), (270, 90), (350, 10)])
def test_nav_yaw_is_minus_the_heading_in_radians_within_180(heading, yaw_deg):
    assert math.degrees(bridge.moos_yaw(heading)) == pytest.approx(yaw_deg)


def test_lat_long_of_the_grid_about_the_datum():
    datum = Datum(43.8253, -70.3304)
    assert bridge.local_to_geodetic(0.0, 0.0, datum) == (43.8253, -70.3304)
    lat, lon = bridge.local_to_geodetic(1000.0, 1000.0, datum)
    # 1 km north: 1000 / 111.3 km per degree; 1 km east shrinks with cos(latitude)
    assert lat - 43.8253 == pytest.approx(1000.0 / (math.pi * 6378137.0 / 180.0), rel=1e-9)
    assert lon + 70.3304 == pytest.approx((lat - 43.8253) / math.cos(math.radians(43.8253)), rel=1e-9)


def test_thrust_is_percent_of_the_vehicles_limit_and_the_rudder_degrees_clipped_at_its_limit():
    vehicle = get_vehicle("remus100")
    actuators = bridge.Actuators()
    actuators.receive("DESIRED_THRUST", 24.0)
    actuators.receive("DESIRED_RUDDER", 5.0)
    thrust, rudder = actuators.command(vehicle)
    assert thrust == pytest.approx(0.24 * vehicle.max_thrust)
    assert rudder == pytest.approx(math.radians(5.0))
    actuators.receive("DESIRED_THRUST", 250.0)
    actuators.receive("DESIRED_RUDDER", -100.0)  # pMarinePIDV22's maxrudder
    assert actuators.command(vehicle) == (vehicle.max_thrust, -vehicle.max_rudder)


@pytest.mark.parametrize("bad", ["fast", "nan", float("inf"), None, True, ""])
def test_a_malformed_desired_value_is_ignored_and_counted(bad):
    actuators = bridge.Actuators()
    actuators.receive("DESIRED_RUDDER", 7.0)
    assert actuators.receive("DESIRED_RUDDER", bad) is False
    assert actuators.rudder == 7.0
    assert actuators.malformed == {"DESIRED_RUDDER": 1}
    assert actuators.receive("DESIRED_RUDDER", "-3.5") is True  # a number posted as a string
    assert actuators.rudder == -3.5


def test_moos_time_makes_steps_due_at_t0_plus_k_dt():
    clock = bridge.MoosClock(t0=1000.0, dt=0.05)
    assert clock.due(999.0, 0) == 0
    assert clock.due(1000.0, 0) == 0
    assert clock.due(1000.05, 0) == 1
    assert clock.due(1001.0, 0) == 20
    assert clock.due(1001.0, 20) == 0
    assert clock.due(1001.26, 20) == 5
    assert clock.moos_time(25) == pytest.approx(1001.25)


def test_the_moving_frame_on_the_moos_grid():
    placement = bridge.Placement(origin=(100.0, -50.0), u_sub=1.5)
    assert placement.to_moos(-60.0, 5.89, 10.0) == pytest.approx((55.0, -44.11))
    assert placement.from_moos(*placement.to_moos(3.0, 4.0, 7.0), 7.0) == pytest.approx((3.0, 4.0))


def test_node_report_and_hull_seglist_read_as_moos_writes_them():
    placement = bridge.Placement((0.0, 0.0), 1.5)
    report = bridge.submarine_report(20.0, 1020.0, placement)
    fields = dict(part.split("=", 1) for part in report.split(","))
    assert fields["NAME"] == "submarine" and float(fields["X"]) == pytest.approx(30.0)
    assert float(fields["HDG"]) == 90.0 and float(fields["SPD"]) == 1.5 and float(fields["TIME"]) == 1020.0
    outline = bridge.hull_seglist([0.0, 10.0, 10.0], [0.0, 0.0, 5.0], 2.0, placement)
    assert outline.startswith("pts={3.00,0.00:13.00,0.00:13.00,5.00},label=submarine_hull")


def test_the_appcast_string_has_moos_separators_and_the_warnings_counts():
    text = bridge.appcast("nearsub_sim", "alpha", 7, {"a": 1}, ["e1", "e2"], {"malformed DESIRED_RUDDER": 3})
    fields = text.split("!@#")
    assert fields[:4] == ["proc=nearsub_sim", "iter=7", "node=alpha", "iter=7"]
    assert fields[4].startswith("messages=a ") and fields[4].endswith("!@")
    assert "events_total=2" in fields and "events=e1!@e2" in fields
    assert "run_warning_total=3" in fields and "run_warnings=3:malformed DESIRED_RUDDER" in fields


def test_the_moos_sim_flies_the_missions_own_sim_core_to_the_same_bits():
    """Steps driven by MOOS time with constant actuators give the SimCore's own states."""
    config = sim_config(parse_moos(ALPHA, "alpha.moos"))
    mission = sim_mission(config)
    sim = MoosSim(mission, config, t0=5000.0)
    sim.receive("DESIRED_THRUST", 24.0)
    sim.receive("DESIRED_RUDDER", 10.0)
    posts = dict(sim.advance(5000.0 + 30.0))
    assert sim.steps == round(30.0 / mission.dt)

    reference = cores.SimCore(mission)
    reference.startup()
    thrust, rudder = 0.24 * mission.vehicle_model.max_thrust, math.radians(10.0)
    for step in range(sim.steps):
        reference.new_mail({"input": Input(step=step, t=step * mission.dt, source="t", X_prop=thrust, delta_r=rudder)})
        reference.iterate(step, step * mission.dt)
    np.testing.assert_array_equal(reference.x, cores.state_array(sim.state))
    assert posts["NAV_X"] == sim.state.x and posts["NAV_Y"] == sim.state.y
    assert posts["NAV_HEADING"] == bridge.compass_heading(sim.state.psi)
    assert 0.5 < posts["NAV_SPEED"] < 1.3  # accelerating towards ~1.2 m/s at 24 % of REMUS's thrust
    assert "NAV_LAT" in posts and "NODE_REPORT" not in posts  # a datum, no submarine
    # a positive rudder turns the bow clockwise: the heading grew from 180
    assert 180.0 < posts["NAV_HEADING"] < 360.0
    assert sim.advance(5000.0 + 30.0) == []  # no step due: nothing new
    assert sim.lag(5000.0 + 30.0) == 0.0 and sim.lag(5000.0 + 31.5) == pytest.approx(1.5)


def test_a_collision_with_the_submarine_is_posted_and_ends_the_stepping():
    config = config_of("  u_sub = 1.5\n  submarine = true\n  interaction = off\n  start_pos = x=-20, y=8, heading=180")
    mission = sim_mission(config)
    sim = MoosSim(mission, config, t0=0.0)
    posts = sim.report()
    assert {"NODE_REPORT", "VIEW_SEGLIST"} <= {key for key, _ in posts}
    sim.receive("DESIRED_THRUST", 100.0)
    found = dict(sim.advance(60.0))
    assert "NEARSUB_COLLISION" in found and found["NEARSUB_END"].startswith("collision")
    assert "NEARSUB_CLOSE_CALL" in found or any("close_call" in e for e in sim.events)
    assert sim.advance(120.0) == []


def test_a_running_mission_as_pmarineviewer_sees_it():
    from pathlib import Path

    from nearsub.common.mission.schema import load_mission
    from nearsub.common.moos.watch import MissionWatch

    mission = load_mission(Path(__file__).parent.parent / "missions" / "overtake_stern_nuv.toml")
    watch = MissionWatch(mission, clock=lambda: 5000.0)
    name = mission.vehicle_name
    state = {"t": 10.0, "step": 200, "u": 1.75, "v": 0.0, "r": 0.0, "x": -42.5, "y": 5.89, "psi": 0.0}
    (variable, report), *rest = watch.translate(f"nearsub/{mission.name}/{name}/state", state)
    assert variable == "NODE_REPORT" and rest == []
    fields = dict(part.split("=", 1) for part in report.split(","))
    assert fields["NAME"] == name and float(fields["X"]) == pytest.approx(-42.5 + 15.0)  # u_sub 1.5 for 10 s
    assert float(fields["HDG"]) == 90.0 and float(fields["TIME"]) == 5000.0
    scene = dict(watch.scene())
    assert scene["NODE_REPORT"].startswith("NAME=submarine,X=15.00,Y=0.00")
    assert scene["VIEW_SEGLIST"] == "pts={-45.00,5.89:15.00,5.89},label=" + name + "_track,edge_color=white"
    assert scene["VIEW_POINT"] == f"x=15.00,y=5.89,label={name}_wpt1,vertex_size=4"
    assert watch.translate(f"nearsub/{mission.name}/{name}/state/@every5", state) == []
    assert watch.translate(f"nearsub/{mission.name}/{name}/state", state | {"t": 10.2}) == []  # within 0.25 s
    assert len(watch.translate(f"nearsub/{mission.name}/{name}/state", state | {"t": 10.25})) == 1
    event = {"t": 10.0, "kind": "close_call", "detail": "close call at (1, 2)"}
    assert dict(watch.translate(f"nearsub/{mission.name}/events/sim", event))["NEARSUB_CLOSE_CALL"] == event["detail"]
