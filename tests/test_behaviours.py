"""Helm behaviours as pure functions (thesis sections 5.7 and 6.3)."""

import math

import numpy as np
import pytest

from nearsub.common.autonomy.behaviours import (
    gamma_from_m11,
    lead_point,
    modified_lead_point,
    nuv_heading_offset,
    speed_policy,
)
from nearsub.common.physics.vehicles import REMUS100


def test_lead_point_is_ahead_of_the_foot_and_clamped_at_the_waypoint():
    prev, nxt = np.array([0.0, 0.0]), np.array([100.0, 0.0])
    assert lead_point(prev, nxt, np.array([10.0, 5.0]), 8.0).tolist() == [18.0, 0.0]
    assert lead_point(prev, nxt, np.array([97.0, 5.0]), 8.0).tolist() == [100.0, 0.0]


def test_lead_damper_lengthens_the_lead_on_the_track():
    prev, nxt = np.array([0.0, 0.0]), np.array([100.0, 0.0])
    on_track = lead_point(prev, nxt, np.array([10.0, 0.0]), 8.0, lead_damper=1.0)
    assert on_track.tolist() == [10.0 + 8.0 * 3.0, 0.0]


def test_modified_lead_point_crabs_into_the_cross_flow():
    # A track-line straight across the flow (beta = 90 deg): (6.2) gives d_off = alpha d_lead U_ot / U_sub.
    prev, nxt, pos = np.array([0.0, 0.0]), np.array([0.0, 50.0]), np.array([0.0, 10.0])
    lead = modified_lead_point(prev, nxt, pos, d_lead=4.0, u_ot=0.25, u_sub=1.5, alpha=1.0)
    assert lead == pytest.approx([4.0, 10.0 + 4.0 * 0.25 / 1.5])
    heading = math.degrees(math.atan2(lead[1] - pos[1], lead[0] - pos[0]))
    assert 0 < heading < 10  # "the UUV only needs to orient between +/-10 degrees" (section 6.3.2)


def test_modified_lead_point_on_a_track_along_the_flow_is_the_standard_one():
    prev, nxt, pos = np.array([0.0, 0.0]), np.array([50.0, 0.0]), np.array([10.0, 0.0])
    assert modified_lead_point(prev, nxt, pos, 4.0, 0.25, 1.5, 1.0).tolist() == [14.0, 0.0]


@pytest.mark.parametrize("lag, expected", [(0.0, 0.0), (0.5, 0.5), (1.0, 1.0), (3.0, 1.0), (-2.0, -1.0)])
def test_speed_policy_saturates_at_one_uuv_length(lag, expected):
    length, u_sub, u_ot = 1.33, 1.5, 0.25
    prev, nxt = np.array([0.0, 0.0]), np.array([0.0, 50.0])  # across the flow: cos(beta) = 0
    pos = np.array([-lag * length, 10.0])  # behind the foot by lag * L in the direction of U_sub
    speed = speed_policy(prev, nxt, pos, u_sub, u_ot, length)
    assert speed == pytest.approx(u_sub + u_ot * expected)


def test_gamma_matches_the_thesis_values():
    # (6.4) at the thesis M11 of the three vehicles gives 5.21 / 1.30 / 1.03 (section 6.3.1).
    assert [round(float(gamma_from_m11(m)), 2) for m in (33.6, 212.9, 6020.0)] == [5.21, 1.30, 1.03]


def test_compensation_turns_the_bow_against_the_interaction_moment():
    """Where N_s turns the bow in (N_s < 0 on the +y side), the compensated heading turns it away
    (Delta psi > 0), and the Munk moment N_uv u v at that heading opposes N_s (docs/design.md, "Thesis errata" 5)."""
    u_d, n_s = 1.5, -0.4
    delta = nuv_heading_offset(n_s, u_d, REMUS100.N_uv, gamma=1.0)
    assert delta > 0
    v = -u_d * math.sin(delta)  # the course stays on the track, the bow is Delta psi off it
    munk = REMUS100.N_uv * u_d * v
    assert munk == pytest.approx(-n_s, rel=1e-3)
