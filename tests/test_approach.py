"""Closest approaches (common/analysis/approach.py) against geometry checked by hand: a UUV beside
the submarine's parallel middle body, one behind the stern tip, two UUVs side by side; and the
figures of a logged mission."""

import json

import numpy as np
import pytest

from nearsub.common.analysis.approach import Track, approaches, closest_pair, hull_approach
from nearsub.common.physics import encounters
from nearsub.common.physics.hull import (
    L_SUB,
    R_SUB,
    SUB_CB_FROM_NOSE,
    SUB_STERN_X,
    SUBOFF_JOINTS_M,
    explorer_cb_from_nose,
)
from nearsub.common.physics.vehicles import get_vehicle

REMUS = get_vehicle("remus100")


def _track(x, y, psi, vehicle=REMUS) -> Track:
    x, y, psi = (np.atleast_1d(np.asarray(a, dtype=float)) for a in np.broadcast_arrays(x, y, psi))
    steps = np.arange(len(x))
    return Track(steps, 0.05 * steps, x, y, psi, vehicle.length, vehicle.diameter)


def test_a_uuv_beside_the_parallel_middle_body_is_its_gap_away_beside_its_own_midbody():
    # Heading 0 at y = R_sub + D/2 + gap: the two parallel middle bodies face each other, gap apart.
    # The track passes farther out first and comes closest at its last state (t = 0.15 s).
    gap = 0.37
    y = R_SUB + REMUS.diameter / 2 + gap
    found = hull_approach(_track(-5.0, [y + 3.0, y + 1.0, y + 0.2, y], 0.0))
    assert found.clearance == pytest.approx(gap, abs=1e-9)
    assert found.t == pytest.approx(0.15)
    # The closest hull points lie across the UUV's own parallel body (between its bow ellipse
    # of 2R and its stern paraboloid of 4R, thesis (3.1)/(3.2)).
    cb = explorer_cb_from_nose(REMUS.length, REMUS.diameter)
    radius = REMUS.diameter / 2
    assert -5.0 + cb - (REMUS.length - 4 * radius) - 1e-9 <= found.hull_x <= -5.0 + cb - 2 * radius + 1e-9
    assert found.r_long == pytest.approx(found.hull_x / L_SUB)
    assert SUB_CB_FROM_NOSE - SUBOFF_JOINTS_M[1] < found.hull_x < SUB_CB_FROM_NOSE - SUBOFF_JOINTS_M[0]


def test_a_uuv_behind_the_stern_tip_is_its_gap_from_the_tip_not_its_centre_distance():
    # On the axis, nose forward: each body lies on its side of the plane through its tip, so the
    # least distance is tip to tip (nose to stern tip), whatever the two curvatures.
    gap = 2.5
    nose_ahead = explorer_cb_from_nose(REMUS.length, REMUS.diameter)
    x = SUB_STERN_X - gap - nose_ahead
    found = hull_approach(_track(x, 0.0, 0.0))
    assert found.clearance == pytest.approx(gap, abs=1e-4)  # the stern polyline is exact to 0.1 mm
    assert found.hull_x == pytest.approx(SUB_STERN_X, abs=1e-3)
    assert found.r_long == pytest.approx(SUB_STERN_X / L_SUB, abs=1e-4)  # -0.539: the stern tip
    assert found.clearance < abs(x - SUB_STERN_X) - 0.5  # not the centre's distance


def test_a_uuv_overlapping_the_hull_has_a_negative_clearance():
    found = hull_approach(_track(0.0, R_SUB + REMUS.diameter / 2 - 0.05, 0.0))
    assert found.clearance == pytest.approx(-0.05, abs=1e-9)


def test_the_closest_pair_is_the_surface_gap_at_the_step_they_came_closest():
    # Two REMUS 100s abreast, closing from 5 m to 1 m between axes and opening again.
    axes = np.array([5.0, 3.0, 1.0, 2.0, 4.0])
    a, b = _track(0.0, 0.0 * axes, 0.0), _track(0.0, axes, 0.0)
    c = _track(0.0, 40.0 + 0.0 * axes, 0.0)  # far away: never the closest pair
    found = closest_pair({"auv1": a, "auv2": b, "far": c})
    assert found.vehicles == ("auv1", "auv2")
    assert found.clearance == pytest.approx(1.0 - REMUS.diameter, abs=1e-12)
    assert found.t == pytest.approx(0.10)
    assert closest_pair({"auv1": a}) is None


def test_crossing_uuvs_overlap_and_a_tip_passing_a_side_counts_from_the_tip():
    # auv2 crosses auv1's axis at right angles (step 2: the axes cross, a collision of one
    # diameter's overlap); at the other steps its CB is 3 m abeam of auv1's CB, to either side.
    a = Track(np.arange(5), 0.05 * np.arange(5), *(np.zeros(5),) * 3, REMUS.length, REMUS.diameter)
    b = _track(0.0, [6.0, 3.0, 0.0, -3.0, -6.0], -np.pi / 2)
    found = closest_pair({"auv1": a, "auv2": b})
    assert found.clearance == pytest.approx(-REMUS.diameter, abs=1e-12)
    assert found.t == pytest.approx(0.10)
    # Nose to nose, 2 m between the tips: the gap is tip to tip, not CB to CB.
    nose = encounters.Capsule.of(REMUS.length, REMUS.diameter)
    ahead = _track(2 * (nose.ahead + nose.radius) + 2.0, 0.0, np.pi)
    gap = closest_pair({"auv1": _track(0.0, 0.0, 0.0), "auv2": ahead}).clearance
    assert gap == pytest.approx(2.0, abs=1e-9)


def test_without_a_submarine_there_is_no_hull_approach():
    found = approaches({"auv1": _track(0.0, 30.0, 0.0), "auv2": _track(0.0, 35.0, 0.0)}, submarine=False)
    assert found.hull == {}
    assert found.pair.clearance == pytest.approx(5.0 - REMUS.diameter)
    text = "\n".join(found.lines())
    assert "auv1 and auv2: closest 4.81 m apart at t=0.00 s" in text


def test_log_info_reports_each_vehicles_hull_approach_and_the_closest_pair(tmp_path, capsys):
    """launch_two logged for 10 s: `log info --json` gives what the in-process run's own states
    give (the fleet figures measure the same clearances pose by pose)."""
    from test_every_mission_views import logged_run

    from conftest import ROOT
    from nearsub.common.analysis.fleet import fleet_figures
    from nearsub.common.mission.cores import run_mission
    from nearsub.common.mission.schema import load_mission
    from nearsub.tools.cli import main

    mission = load_mission(ROOT / "missions" / "launch_two.toml", ["time_limit=10.0"])
    path = tmp_path / "launch_two.mcap"
    logged_run(mission, path)
    assert main(["log", "info", "--json", str(path)]) == 0
    found = json.loads(capsys.readouterr().out)["approaches"]
    figures = fleet_figures(mission, run_mission(mission))
    for name in ("auv1", "auv2"):
        hull = found["hull"][name]
        per_pose = figures.vehicle(name).hull_clearance  # the grids' clearance: within 1 mm near the hull
        assert hull["clearance_m"] == pytest.approx(per_pose.min(), abs=2e-3)
        assert hull["t"] == pytest.approx(figures.vehicle(name).times[np.argmin(per_pose)], abs=0.5)
        assert hull["r_long"] == pytest.approx(hull["hull_x_m"] / L_SUB)
    gap, t = figures.closest_pair[("auv1", "auv2")]
    assert found["closest_pair"] == {"vehicles": ["auv1", "auv2"], "clearance_m": gap, "t": t}
    assert main(["log", "info", str(path)]) == 0
    text = capsys.readouterr().out
    assert f"auv1 and auv2: closest {gap:.2f} m apart at t={t:.2f} s" in text
    assert "auv1: closest to the hull" in text and "R_long" in text
