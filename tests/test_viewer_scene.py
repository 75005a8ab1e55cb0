"""The viewer's scene model: what the page draws, from a mission and a run's messages."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from nearsub.common.mission.schema import load_mission
from nearsub.common.physics.hull import L_SUB, SUB_BOW_X, SUB_STERN_X
from nearsub.common.runtime.messages import Event, Forces, HelmProgress, MissionEnd, State, encode
from nearsub.common.viewer.scene import SceneModel, acting_band, feed_payload, force_reference, static_scene

MISSIONS = Path(__file__).resolve().parent.parent / "missions"


@pytest.fixture(scope="module")
def overtake():
    return load_mission(MISSIONS / "overtake_stern_standard.toml")


@pytest.fixture(scope="module")
def alpha():
    return load_mission(MISSIONS / "alpha.toml")


def state(step, x, y, psi=0.0, dt=0.05, u=1.0):
    return State(step=step, t=step * dt, source="sim", u=u, v=0.0, r=0.0, x=x, y=y, psi=psi)


def test_static_scene_draws_the_hull_to_scale_and_the_legs_from_the_start(overtake):
    scene = static_scene(overtake)
    hull = np.array(scene["hull"])
    assert hull[:, 0].max() == pytest.approx(SUB_BOW_X, abs=1e-3)
    assert hull[:, 0].min() == pytest.approx(SUB_STERN_X, abs=1e-3)
    assert np.ptp(hull[:, 0]) == pytest.approx(L_SUB, abs=1e-2)
    (leg,) = scene["legs"]
    assert leg["track"] == [[-60.0, 5.89], [0.0, 5.89]]  # the first track-line starts at the start
    assert scene["vehicle"]["name"] == "sdv"
    assert scene["frame"].startswith("submarine frame")
    json.dumps(scene)  # what the server sends


def test_alpha_has_no_submarine_no_band_and_chained_track_lines(alpha):
    scene = static_scene(alpha)
    assert scene["hull"] is None
    assert scene["band"]["rects"] == [] and "no submarine" in scene["band"]["note"]
    survey, home = scene["legs"]
    assert survey["track"][0] == [0.0, -20.0]
    assert home["track"][0] == survey["points"][-1]  # the return leg starts where the survey ended
    assert scene["frame"].startswith("earth-fixed frame")


def test_acting_band_is_where_the_constraints_hold_for_the_sdv_on_both_sides(overtake):
    # The SDV's lateral window (constraints (4.4)/(4.5)): 5.546 m <= |y| <= 6.241 m.
    band = acting_band(overtake)
    upper, lower = band["rects"]
    assert upper["y0"] == pytest.approx(5.546, abs=0.01)
    assert upper["y1"] == pytest.approx(6.241, abs=0.01)
    assert (lower["y0"], lower["y1"]) == (-upper["y1"], -upper["y0"])
    assert upper["x0"] == pytest.approx(-0.7 * L_SUB, abs=1e-3) and upper["x1"] == pytest.approx(0.7 * L_SUB, abs=1e-3)
    assert upper["y0"] <= overtake.start.y <= upper["y1"]  # the mission starts inside it


def test_band_is_absent_when_the_interaction_is_off(overtake):
    off = overtake.model_copy(update={"apps": overtake.apps.model_copy(deep=True)})
    off.apps.sim.interaction = "off"
    assert acting_band(off)["rects"] == []
    assert acting_band(None)["rects"] == []


def test_vehicle_outline_is_placed_at_the_state_and_points_along_the_heading(overtake):
    model = SceneModel.for_mission(overtake)
    psi = math.radians(30.0)
    model.feed(state(10, -20.0, 6.0, psi))
    vehicle = model.frame()["vehicle"]
    outline = np.array(vehicle["outline"])
    assert (vehicle["x"], vehicle["y"], vehicle["psi"]) == (-20.0, 6.0, psi)
    length = overtake.vehicle_model.length
    along = (outline - [-20.0, 6.0]) @ [math.cos(psi), math.sin(psi)]
    across = (outline - [-20.0, 6.0]) @ [-math.sin(psi), math.cos(psi)]
    assert np.ptp(along) == pytest.approx(length, rel=0.02)  # long axis along the heading
    assert np.ptp(across) == pytest.approx(overtake.vehicle_model.diameter, rel=0.05)


def test_trail_keeps_a_point_per_spacing_and_ends_at_the_vehicle(overtake):
    model = SceneModel.for_mission(overtake)
    model.trail_spacing = 1.0
    for step in range(101):  # 10 m in 0.1 m steps
        model.feed(state(step, -60.0 + 0.1 * step, 5.89))
    frame = model.frame()
    trail = frame["trail"]
    assert 10 <= len(trail) <= 12
    assert trail[0] == [-60.0, 5.89] and trail[-1] == [-50.0, 5.89]
    assert all(b[0] > a[0] for a, b in zip(trail, trail[1:], strict=False))


def test_frame_at_a_time_shows_the_past_for_replay(overtake):
    model = SceneModel.for_mission(overtake)
    model.trail_spacing = 0.5
    for step in range(200):
        model.feed(state(step, -60.0 + 0.05 * step, 5.89))
    model.feed(Event(step=50, t=2.5, source="sim", kind="close_call", detail="close", data={"x": -57.5, "y": 5.89}))
    model.feed(MissionEnd(step=200, t=10.0, source="clock", outcome="collision"))
    early = model.frame(2.0)
    assert early["vehicle"]["step"] == 40 and early["vehicle"]["x"] == pytest.approx(-58.0)
    assert early["events"] == [] and early["status"]["outcome"] is None
    assert max(x for x, _ in early["trail"]) <= -58.0 + 1e-9
    late = model.frame(10.0)
    assert [e["kind"] for e in late["events"]] == ["close_call"]
    assert late["status"]["outcome"] == "collision"
    assert model.time_range() == (0.0, 199 * 0.05)
    assert model.frame(-1.0)["vehicle"] is None


def test_a_decimal_time_reaches_the_state_of_its_binary_step(overtake):
    """A page scrubbed to 11.7 s must draw the state at 117 x 0.1 = 11.700000000000001 s."""
    model = SceneModel.for_mission(overtake)
    for step in range(118):
        model.feed(state(step, -60.0 + 0.1 * step, 5.89, dt=0.1))
    assert model.time_range()[1] == 117 * 0.1 > 11.7
    model.feed(Event(step=117, t=117 * 0.1, source="sim", kind="collision", detail="hull", data={}))
    model.feed(MissionEnd(step=118, t=118 * 0.1, source="clock", outcome="collision"))
    end = model.frame(11.7)
    assert end["vehicle"]["step"] == 117 and [e["kind"] for e in end["events"]] == ["collision"]
    assert end["status"]["outcome"] == "collision"
    assert model.frame(11.65)["vehicle"]["step"] == 116 and model.frame(11.65)["events"] == []


def test_applied_force_arrow_is_weighted_rotated_and_scaled(overtake):
    model = SceneModel.for_mission(overtake)
    model.feed(state(10, -20.0, 6.0, math.pi / 2))
    reference = force_reference(overtake)
    model.feed(
        Forces(
            step=10,
            t=0.5,
            source="sim",
            X_s=0.0,
            Y_s=2.0 * reference,  # body +y (to port) at heading 90 deg points along frame -x
            N_s=-0.25 * reference * overtake.vehicle_model.length,
            std_X=0.0,
            std_Y=0.0,
            std_N=0.0,
            weight=0.5,
            in_domain=True,
            constraints_ok=True,
        )
    )
    forces = model.frame()["forces"]
    assert forces["Y_s"] == pytest.approx(reference, abs=1e-3)  # weight times the prediction
    (x0, y0), (x1, y1) = forces["arrow"]
    length = overtake.vehicle_model.length
    assert (x0, y0) == (-20.0, 6.0)
    assert x1 == pytest.approx(-20.0 - length, abs=1e-3) and y1 == pytest.approx(6.0, abs=1e-3)
    assert forces["moment_fraction"] == pytest.approx(-0.125)


def test_events_take_the_vehicle_position_when_they_carry_none(overtake):
    model = SceneModel.for_mission(overtake)
    model.feed(state(100, -30.0, 5.9))
    model.feed(Event(step=100, t=5.0, source="launcher", kind="swap", detail="helm-1 -> helm-2 at step 100"))
    model.feed(Event(step=100, t=5.0, source="launcher", kind="app_joined", detail="helm-2 joined"))
    (swap,) = model.frame()["events"]
    assert (swap["kind"], swap["x"], swap["y"], swap["marked"]) == ("swap", -30.0, 5.9, True)


def test_messages_seen_twice_are_kept_once(overtake):
    """The live view reads the log written so far and also subscribes: overlaps count once."""
    model = SceneModel.for_mission(overtake)
    event = Event(step=5, t=0.25, source="sim", kind="close_call", detail="x", data={"x": 1.0, "y": 2.0})
    for _ in range(2):
        model.feed(state(5, -30.0, 5.9))
        model.feed(event)
    assert len(model.poses) == 1 and len(model.frame()["events"]) == 1


def test_status_reports_behaviour_and_achieved_warp(overtake):
    model = SceneModel.for_mission(overtake)
    for step in range(0, 81, 5):  # 4 s of simulated time in 2 s of wall time: warp 2
        model.feed(state(step, -60.0, 5.89), wall=100.0 + step * 0.05 / 2)
    model.feed(
        HelmProgress(
            step=80, t=4.0, source="helm", behaviour="waypoints", leg=0, waypoint_index=0, waypoints_reached=0, psi_d=0
        )
    )
    status = model.frame(now=102.0)["status"]
    assert status["achieved_warp"] == pytest.approx(2.0, rel=1e-6)
    assert status["requested_warp"] == overtake.warp
    assert status["behaviour"] == "waypoints" and status["step"] == 80
    assert model.frame(now=104.0)["status"]["achieved_warp"] == 0.0  # no state for 2 s: not advancing


def test_feed_payload_skips_malformed_and_unused_messages(overtake):
    model = SceneModel.for_mission(overtake)
    key = "nearsub/overtake_stern_standard/sdv/state"
    assert feed_payload(model, key, encode(state(1, -59.0, 5.89)))
    assert not feed_payload(model, key, b"\xc1 not msgpack")
    assert not feed_payload(model, "nearsub/overtake_stern_standard/clock/tick", b"")
    assert len(model.poses) == 1


def test_the_outcome_shows_from_the_last_state_on(overtake):
    """The mission end is labelled with the step after the last state; a replay scrubbed to the
    last state shows the outcome."""
    model = SceneModel.for_mission(overtake)
    for step in range(10):
        model.feed(state(step, -60.0, 5.89))
    model.feed(MissionEnd(step=10, t=0.5, source="clock", outcome="collision"))
    assert model.frame(9 * 0.05)["status"]["outcome"] == "collision"
    assert model.frame(8 * 0.05)["status"]["outcome"] is None
    assert model.frame()["status"]["outcome"] == "collision"


def test_page_assets_ship_with_the_package_and_fetch_nothing_else():
    from nearsub.tools.view_server import static_files

    files = static_files()
    assert {"/", "/index.html", "/viewer.js", "/viewer.css"} <= set(files)
    for body, _ in files.values():
        text = body.decode()
        assert "http://" not in text and "https://" not in text  # no network fetches


def test_every_vehicle_of_the_keys_gets_its_own_track_and_the_first_leads(overtake):
    model = SceneModel.for_mission(overtake)
    community = "nearsub/overtake_stern_standard"
    for step in range(5):
        feed_payload(model, f"{community}/bravo/state", encode(state(step, -40.0 + step, 20.0)))
        feed_payload(model, f"{community}/alfa/state", encode(state(step, -60.0 + step, 5.89)))
    stray = Event(step=3, t=0.15, source="helm", kind="large_stray", detail="off the track", data={})
    assert feed_payload(model, f"{community}/events/bravo/helm-1", encode(stray))
    frame = model.frame()
    assert [v["name"] for v in frame["vehicles"]] == ["alfa", "bravo"]
    assert frame["vehicle"]["name"] == "alfa" and frame["vehicle"]["x"] == -56.0
    bravo = frame["vehicles"][1]
    assert bravo["vehicle"]["x"] == -36.0 and bravo["trail"][0] == [-40.0, 20.0]
    assert bravo["vehicle"]["length"] == overtake.vehicle_model.length  # not a library name: the mission's vehicle
    [event] = frame["events"]
    assert event["vehicle"] == "bravo" and (event["x"], event["y"]) == (-37.0, 20.0)  # bravo's pose at 0.15 s


def test_the_replay_of_a_damaged_log_says_what_it_kept(alpha, tmp_path, capsys):
    from nearsub.common.runtime.logfile import LogWriter
    from nearsub.tools.view_server import ReplaySource

    path = tmp_path / "cut.mcap"
    writer = LogWriter(path)
    for step in range(3000):
        writer.write("nearsub/alpha/state", encode(state(step, 0.1 * step, 0.0)), step * 0.05)
    writer._file.flush()  # a crash: never finished
    path.write_bytes(path.read_bytes()[:-100])
    source = ReplaySource(path, alpha)
    assert source.scene["damage"].startswith("the file was not finished")
    assert capsys.readouterr().err.startswith(f"nearsub view: {path}: the file was not finished")
