"""The increment mode with the LF in the loop: [LF(x) - LF_free(x)] + w(x) delta(x_c) at every pose
(common/surrogate/interaction.py), and the tip-clearance guard on the N_uv offset of (6.1)."""

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import ALPHA
from nearsub.common.autonomy import behaviours
from nearsub.common.hydro import low_fidelity as hydro_lf
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.physics import proximity
from nearsub.common.physics.dynamics import body_forces
from nearsub.common.physics.hull import R_SUB
from nearsub.common.physics.vehicles import NPS_AUV_II, REMUS100, SDV
from nearsub.common.surrogate import domain
from nearsub.common.surrogate.interaction import (
    DELTA_TAPER,
    LF_CUT,
    LF_FRACTION,
    LF_FULL,
    blend_weight,
    increment_table,
    interaction_at,
    lf_in_loop_increment,
    lf_reach_weight,
)
from nearsub.common.surrogate.model import load_surrogate
from nearsub.common.surrogate.validation import read_points_file

RHO = 1025.0


@pytest.fixture(scope="module")
def model():
    surrogate = load_surrogate()
    assert surrogate.kind == "lf_in_loop"  # the shipped model
    return surrogate


def states_at(x, y, psi_deg, u=1.5):
    x, y, psi = np.broadcast_arrays(*(np.atleast_1d(np.asarray(a, dtype=float)) for a in (x, y, np.radians(psi_deg))))
    zeros = np.zeros_like(x)
    return np.column_stack([np.full_like(x, u), zeros, zeros, x, y, psi])


def no_jump(values, factor=4.0):
    """Steps between neighbours of a fine sweep (n, 3): none larger than `factor` times the larger
    of its two neighbouring steps (plus a hair), which a smooth function on a fine grid satisfies
    and a jump or a ramp much steeper than the rest does not."""
    steps = np.abs(np.diff(values, axis=0))
    neighbours = np.maximum(np.vstack([steps[1:], steps[-1:]]), np.vstack([steps[:1], steps[:-1]]))
    return np.all(steps <= factor * neighbours + 1e-9 * np.abs(values).max(axis=0))


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_increment_is_continuous_in_heading_across_the_trained_range(model, side):
    """The SDV beside the afterbody: psi through +/-2 deg in 0.002 deg steps (the old blend ramped
    the whole interaction off over 0.08 deg there, 40 of these steps). The increment (and the force
    the dynamics add) moves smoothly, and it does not vanish beyond 2 deg: the LF carries it."""
    for edge in (2.0, -2.0):
        psi = np.linspace(edge - 0.5, edge + 0.5, 501)
        seen = interaction_at(model, states_at(-30.0, side * 5.9, psi), SDV, RHO, "increment")
        assert np.all(np.isfinite(seen.applied))
        assert no_jump(seen.applied)
        np.testing.assert_array_equal(seen.delta_weight, seen.delta_weight[0])  # never of psi
        outer = np.abs(psi) > 2.0
        assert np.all(np.abs(seen.applied[outer, 2]) > 0.3 * np.abs(seen.applied[~outer, 2]).max())
    assert not no_jump(np.where(np.abs(psi) > 2.0, 0.0, 1.0)[:, None] * np.ones((1, 3)))  # the check can fail


def test_increment_is_continuous_across_the_lateral_edge_of_constraint_4_5(model):
    """The SDV moved outwards across (4.5) (2 D_uuv off the hull, y = 6.24 m) in 1 mm steps: delta's
    weight is 1 up to the edge and ramps to 0 over DELTA_TAPER diameters beyond it with smoothstep's
    slope, delta is held at its value on the edge, the LF increment continues without a jump, and
    the total moves by no more than its parts allow."""
    edge = R_SUB + 2.0 * SDV.diameter + 0.5 * (88.86 / 8.575 - 2.0 * R_SUB)  # (4.5): y_dist <= 2 D_uuv + D_sub/2
    y = np.linspace(5.9, 7.0, 1101)
    seen = interaction_at(model, states_at(-30.0, y, 0.0), SDV, RHO, "increment")
    w = seen.delta_weight
    assert np.all(w[y <= edge - 1e-3] == 1.0) and w[-1] == 0.0 and np.all(np.diff(w) <= 0)
    dw = np.abs(np.diff(w))
    ramp = (w > 0) & (w < 1)
    assert abs(ramp.sum() * 1e-3 - DELTA_TAPER * SDV.diameter) < 3e-3  # one D_uuv of 1 mm steps
    assert dw.max() <= 1.5 / ramp.sum() * 1.1  # smoothstep's steepest slope over the ramp's steps
    beyond = (y > edge + 1e-3) & (w > 0)
    np.testing.assert_allclose(seen.model[beyond], seen.model[beyond][:1] * np.ones((beyond.sum(), 1)), rtol=0.02)
    assert np.isnan(seen.model[w == 0]).all() and np.isnan(seen.delta_free[w == 0]).all()  # not asked there
    assert no_jump(seen.lf)  # the LF increment knows nothing of (4.5)
    assert no_jump(seen.viscous)  # nor does the viscous correction
    assert np.all(np.abs(seen.applied[-1]) > 0)  # and it goes on beyond it
    delta = np.where(w[:, None] > 0, seen.model - seen.delta_free, 0.0)
    steps = np.abs(np.diff(seen.applied, axis=0))
    allowed = dw[:, None] * np.abs(delta[1:]) + np.abs(np.diff(seen.lf, axis=0)) + np.abs(np.diff(delta, axis=0))
    allowed += np.abs(np.diff(seen.viscous, axis=0))
    assert np.all(steps <= allowed + 1e-9)


@pytest.mark.parametrize("weighted_only", [False, True])
def test_a_state_alone_gets_the_bits_it_gets_among_others(model, weighted_only):
    """interaction_at of one vehicle (the sim: every row asked and near) equals its row in a batch
    whose other rows are out of the LF's reach or of delta's weight (masked rows, the batch
    engine's `weighted_only`), field by field and bit for bit; the std to rounding (the GP's std
    uses BLAS, `MultiOutputGP.predict_rows`)."""
    near = states_at(np.linspace(-60.0, 60.0, 7), 5.6, np.linspace(-3.0, 3.0, 7))
    far = states_at([0.0, 30.0], [400.0, -9.0], 0.0)  # beyond LF_CUT; beyond (4.5) and its taper
    batch = np.vstack([far[:1], near, far[1:]])
    together = interaction_at(model, batch, SDV, RHO, "increment", weighted_only=weighted_only)
    assert not (together.interaction.weight > 0).all() and not (together.delta_weight > 0).all()
    for k, state in enumerate(near, start=1):
        alone = interaction_at(model, state, SDV, RHO, "increment", weighted_only=weighted_only)
        for name in ("forces", "applied", "model", "lf", "delta_free", "delta_weight", "outside_mask", "lf_held"):
            np.testing.assert_array_equal(getattr(alone, name)[0], getattr(together, name)[k], err_msg=name)
        np.testing.assert_allclose(alone.std[0], together.std[k], rtol=1e-12)
        np.testing.assert_array_equal(alone.interaction.forces, together.interaction.forces[k])


def test_blend_weight_of_the_discrepancy_does_not_depend_on_heading():
    rng = np.random.default_rng(3)
    X = domain.sample_feasible(200, seed=5)
    turned = X.copy()
    turned[:, 3] = rng.uniform(-40.0, 40.0, len(X))
    np.testing.assert_array_equal(blend_weight(turned, heading=False), blend_weight(X, heading=False))
    assert np.any(blend_weight(turned) != blend_weight(turned, heading=False))  # the old blend does


def test_every_query_outside_the_trained_box_is_flagged_with_the_input_named(model):
    cases = [
        (states_at(-30.0, 5.9, 0.5), []),
        (states_at(-30.0, 5.9, 6.0), ["psi_deg"]),
        (states_at(-30.0, -5.9, -6.0), ["psi_deg"]),
        (states_at(-30.0, 7.5, 0.5), ["(4.5)"]),
        (states_at(-30.0, 9.8, 0.5), ["R_lat", "(4.5)"]),
        (states_at(-30.0, 5.9, 0.5, u=0.5), ["u_kn"]),
        (states_at(70.0, 5.9, 0.5), ["R_long"]),
    ]
    for state, names in cases:
        seen = interaction_at(model, state, SDV, RHO, "increment")
        assert seen.outside(0) == names, (state, names)
        assert bool(seen.in_domain[0]) == (not [n for n in names if not n.startswith("(")])
    remus = interaction_at(model, states_at(-30.0, 5.5, 0.5), REMUS100, RHO, "increment")
    assert remus.outside(0) == ["d_ratio"]  # D_sub/D_uuv = 54.3 > 50: clamped, and said so


def test_the_applied_force_is_what_the_dynamics_add(model):
    states = states_at(np.linspace(-45.0, 45.0, 31), 6.1, np.linspace(-10.0, 10.0, 31))
    states[:, 1] = 0.05  # some sway, so (5.11)'s own terms are not zero
    seen = interaction_at(model, states, SDV, RHO, "increment")
    command = np.zeros((len(states), 2))
    added = body_forces(states, command, SDV, seen.interaction) - body_forces(states, command, SDV)
    np.testing.assert_allclose(added, seen.applied, rtol=1e-12, atol=1e-9)
    corrected = seen.lf + seen.delta_weight[:, None] * (seen.model - seen.delta_free) + seen.viscous
    np.testing.assert_allclose(seen.forces, corrected, rtol=1e-13, atol=1e-12)
    assert np.any(seen.viscous != 0.0)  # beside the hull the viscous correction is in the sum


def test_the_increment_holds_no_free_stream_difference_of_the_two_models(model):
    """On the held-out HF points (docs/hydro/validation-points.csv, inside the trained window, where
    delta's weight is 1), the applied increment matches the HF's own increment, HF - HF_free, with
    no offset in X': delta's free-stream part HF_free - LF_free is taken out. Adding delta whole
    would leave an offset of that free-stream difference (which the check sees)."""
    X, hf = read_points_file(Path(__file__).resolve().parents[1] / "docs" / "hydro" / "validation-points.csv")
    finite = np.isfinite(hf).all(axis=1)
    X, hf = X[finite], hf[finite]
    table = increment_table(model)
    increment, _, delta, _, lf, free, w, _, _ = lf_in_loop_increment(
        model, X, X[:, 0] * 88.86, X[:, 1] * 88.86, SDV, table, with_std=False
    )
    full = w == 1.0
    assert full.sum() > 300
    hf_increment = hf - table.coefficients(X)
    offset = np.mean(increment[full] - hf_increment[full], axis=0)
    assert abs(offset[0]) < 1e-5
    whole = np.mean(lf[full] + delta[full] - hf_increment[full], axis=0)
    assert abs(whole[0]) > 3e-5  # what the free-stream part did
    np.testing.assert_allclose(whole - offset, np.mean(free[full], axis=0), rtol=1e-9, atol=1e-12)


def test_forces_topic_publishes_what_the_sim_applied(model):
    mission = load_mission(
        ALPHA,
        [
            "environment.submarine=true",
            "environment.u_sub=1.5",
            "vehicle=sdv",
            "start.x=-30",
            "start.y=5.9",
            "start.speed=1.5",
            "apps.helm.legs=[{points = [[60.0, 5.9]], speed = 1.5, lead = 15.9, lead_to_start = true}]",
            "time_limit=3",
        ],
    )
    result = run_mission(mission, model)
    states = {m.step: m for m in result.topic("state")}
    for message in result.topic("forces"):
        s = states[message.step]
        state = np.array([s.u, s.v, s.r, s.x, s.y, s.psi])
        seen = interaction_at(model, state, SDV, mission.environment.rho, "increment")
        applied = [message.applied_X, message.applied_Y, message.applied_N]
        np.testing.assert_array_equal(applied, seen.applied[0])
        np.testing.assert_array_equal(applied, message.weight * np.array([message.X_s, message.Y_s, message.N_s]))
        assert message.outside == seen.outside(0) and message.in_domain == bool(seen.in_domain[0])


def test_where_the_lf_is_undefined_its_field_is_held_and_flagged(model):
    """The SDV sliding in beside the middle body until it touches the hull: closer than 1 cm to the
    widest radius the LF's field table ends (lf_coefficients is NaN); in the loop the field is held
    at that edge, the forces stay finite and continuous, and the topic's lf_held says so."""
    half = SDV.diameter / 2.0
    y = R_SUB + half + np.linspace(0.05, -0.02, 141)  # 5 cm apart to 2 cm overlap, 0.5 mm steps
    states = states_at(-30.0, y, 0.0)
    inputs, _ = domain.to_inputs(states[:, 3], states[:, 4], 1.5, 0.0, SDV.length, SDV.diameter)
    inputs[:, 4:] = np.clip(inputs[:, 4:], domain.BOUNDS[4:, 0], domain.BOUNDS[4:, 1])
    plain = hydro_lf.lf_coefficients(inputs)
    seen = interaction_at(model, states, SDV, RHO, "increment")
    undefined = np.isnan(plain).any(axis=1)
    assert undefined.any() and not undefined.all()
    np.testing.assert_array_equal(seen.lf_held, undefined)
    assert np.all(np.isfinite(seen.applied))
    assert no_jump(seen.lf)
    increment = domain.to_forces(plain - hydro_lf.lf_free_stream(inputs), 1.0, 1.5, SDV.length, RHO)
    np.testing.assert_allclose(seen.lf[~undefined], increment[~undefined], rtol=1e-12, atol=0)


def test_lf_increment_reaches_out_and_is_cut_off_smoothly():
    clearance = np.linspace(0.0, LF_CUT + 20.0, 28001)
    y = R_SUB + clearance  # beside the parallel middle body, where the clearance is |y| - R_sub
    w = lf_reach_weight(np.zeros_like(y), y)
    assert np.all(w[clearance <= LF_FULL] == 1.0) and np.all(w[clearance >= LF_CUT] == 0.0)
    assert np.abs(np.diff(w)).max() <= 1.5 * (clearance[1] - clearance[0]) / (LF_CUT - LF_FULL) * 1.01


def own_forces(vehicle, u):
    """|drag|, |drag| and |Munk moment at 2 deg| [N, N, N m] of the vehicle's own (5.11) at speed u."""
    munk = vehicle.compensation_N_uv * u**2 * math.sin(math.radians(2.0)) * math.cos(math.radians(2.0))
    return np.abs([vehicle.X_uu * u**2, vehicle.X_uu * u**2, munk])


def largest_fraction(model, vehicle, u, low, high):
    """Largest |LF increment| over the vehicle's own forces (`own_forces`) at psi = 0 anywhere round
    the hull with a clearance between low and high [m]."""
    x, y = np.meshgrid(np.linspace(-50.0 - high, 42.0 + high, 600), np.linspace(0.0, R_SUB + high, 300))
    clearance = proximity.hull_signed_distance(x.ravel(), y.ravel())
    band = (clearance >= low) & (clearance <= high)
    seen = interaction_at(
        model,
        states_at(x.ravel()[band], y.ravel()[band], 0.0, u),
        vehicle,
        RHO,
        "increment",
        with_std=False,
        weighted_only=True,
    )
    assert np.all(np.isfinite(seen.lf))
    return (np.abs(seen.lf) / own_forces(vehicle, u)).max(axis=0)


@pytest.mark.parametrize("vehicle", [REMUS100, NPS_AUV_II, SDV], ids=lambda v: v.name)
def test_lf_increment_is_a_small_fraction_of_the_vehicles_own_forces_where_it_is_cut_off(model, vehicle):
    """Where the reach weight starts to fall (LF_FULL) the LF increment is below LF_FRACTION of the
    vehicle's own drag (X', Y') and 2-deg Munk moment (N') at table 4.2's lowest and highest speed;
    40 m nearer the hull it is not yet, for at least one output (the cut-off is not far beyond
    where it has to be, for the vehicle that sets it)."""
    nearer = []
    for u_kn in (2.0, 5.0):
        u = u_kn * domain.KNOT
        assert np.all(largest_fraction(model, vehicle, u, LF_FULL, LF_FULL + 3.0) < LF_FRACTION)
        nearer.append(largest_fraction(model, vehicle, u, LF_FULL - 40.0, LF_FULL - 37.0).max())
    if vehicle is NPS_AUV_II:
        assert max(nearer) > LF_FRACTION


# --- the guard on the N_uv offset -------------------------------------------------------------
def test_guard_keeps_the_tip_clearance_that_unguarded_compensation_would_break():
    """The SDV 0.6 m off the middle body on a track parallel to it; (6.1) asks for 15 deg of bow
    towards the hull (or away, which swings the stern in). Unguarded, a tip comes within the
    clearance; guarded, it stays at it, and the offset is the largest that does (the pose turned in
    place: horizon 0)."""
    clearance = SDV.diameter
    y = R_SUB + SDV.diameter / 2 + 0.6
    for commanded in (math.radians(-15.0), math.radians(15.0)):
        unguarded = behaviours.tip_clearance(0.0, y, commanded, SDV.length, SDV.diameter)
        assert unguarded < clearance
        guard = behaviours.guard_heading_offset(
            0.0, y, 0.0, commanded, commanded, SDV.length, SDV.diameter, clearance, math.inf, 1.5, 1.5, 0.0
        )
        assert guard.active and guard.saturated
        assert abs(guard.delta_psi) < abs(commanded) and np.sign(guard.delta_psi) == np.sign(commanded)
        kept = behaviours.tip_clearance(0.0, y, guard.delta_psi, SDV.length, SDV.diameter)
        assert kept >= clearance - 2e-3  # the limit is interpolated between samples 0.6 deg apart
        wider = behaviours.tip_clearance(0.0, y, guard.delta_psi * 1.05, SDV.length, SDV.diameter)
        assert wider < clearance  # and it is (nearly) the largest offset that keeps it
    far = behaviours.guard_heading_offset(
        -30.0, 20.0, 0.0, 0.3, 0.3, SDV.length, SDV.diameter, clearance, math.inf, 1.5, 1.5, 0.0
    )
    assert not far.active and not far.saturated and far.delta_psi == 0.3 and math.isinf(far.limit)


def test_guard_rate_limits_the_offset():
    step = math.radians(5.0) * 0.25  # 5 deg/s at a 4 Hz helm
    guard = behaviours.guard_heading_offset(
        -30.0, 20.0, 0.0, 0.3, 0.0, SDV.length, SDV.diameter, 0.53, step, 1.5, 1.5, 0.0
    )
    assert guard.delta_psi == pytest.approx(step) and guard.saturated and not guard.active
    safe = behaviours.guard_heading_offset(
        -30.0, 20.0, 0.0, 0.3, 0.28, SDV.length, SDV.diameter, 0.53, step, 1.5, 1.5, 0.0
    )
    assert safe.delta_psi == 0.3 and not safe.saturated


def test_course_lag_of_the_library_vehicles():
    """The guard's horizon: how long each vehicle's heading loop keeps it on its old course."""
    lags = [float(behaviours.course_lag(v, 1.5)) for v in (REMUS100, NPS_AUV_II, SDV)]
    assert lags == pytest.approx([1.9, 2.2, 6.3], abs=0.05)
    assert behaviours.course_lag(SDV, [1.0, 1.5, 1.52]).tolist() == pytest.approx([8.2, lags[2], lags[2]], abs=0.05)


def test_guard_sees_the_course_an_offset_sets():
    """The SDV 1.4 m (tips) off the bow shoulder (envelope cell R_long 0.39, R_lat 0.076, 15 s in),
    (6.1) asking for 12.3 deg of bow towards the hull: turned in place its tips stay clear, so a
    guard that looked only at the pose let it fly the offset into the hull. Flown along, the course
    brings a tip within the clearance inside the SDV's course lag; the guard cuts the offset to the
    largest whose course keeps it."""
    x, y, track, commanded = 34.41, 5.554, math.radians(4.24), math.radians(-12.34)
    clearance, lag = SDV.diameter, float(behaviours.course_lag(SDV, 1.5))
    args = (x, y, track, commanded, commanded, SDV.length, SDV.diameter, clearance, math.inf, 1.5, 1.5)
    in_place = behaviours.guard_heading_offset(*args, 0.0)
    assert not in_place.active and in_place.delta_psi == commanded

    def course(offset):
        return behaviours.course_tip_clearance(x, y, track + offset, 1.5, 1.5, lag, SDV.length, SDV.diameter)

    assert course(commanded).min() < clearance
    guard = behaviours.guard_heading_offset(*args, lag)
    assert guard.active and guard.saturated and commanded < guard.delta_psi < 0.0
    assert course(guard.delta_psi).min() >= clearance - 2e-3
    assert course(guard.delta_psi * 1.05).min() < clearance


def test_guard_engages_before_the_compensation_reaches_the_hull(model):
    """The compensated SDV envelope cell at R_long 0.39, R_lat 0.076 (2.1 m off the bow shoulder),
    where (6.1) turns the bow towards the hull: the guard engages while the tips are still more than
    the clearance off, and the SDV no longer hits the hull at 23 s."""
    from nearsub.common.analysis import envelope as env
    from nearsub.common.physics.hull import L_SUB

    config = env.EnvelopeConfig(vehicle="sdv", behaviour="nuv_compensation", duration=30.0)
    r_long, r_lat = env.grid_axes(env.EnvelopeConfig(vehicle="sdv"))
    result = run_mission(env.cell_mission(config, r_long[29] * L_SUB, r_lat[7] * L_SUB), model)
    assert result.outcome == "time_limit"
    states = {m.step: m for m in result.topic("state")}
    engaged = [m for m in result.topic("helm") if m.guard_active]
    assert engaged
    first = states[engaged[0].step]
    assert behaviours.tip_clearance(first.x, first.y, first.psi, SDV.length, SDV.diameter) > SDV.diameter


def test_guarded_compensation_mission_keeps_the_tip_clearance(model):
    """N_uv compensation in a mission beside the SDV's afterbody, 0.67 m of tip clearance on the
    track, guard clearance 0.7 m: the helm's progress carries the guard's state, the offset it flew
    never exceeds the guard's limit (which does bind), and the heading it asks for never brings a
    tip closer than the clearance (or than the track itself does). (At 0.72 m on the track the guard
    bound with the panel-trained increment, not with the viscous correction's weaker bow-in moment.)"""
    mission = load_mission(
        ALPHA,
        [
            "environment.submarine=true",
            "environment.u_sub=1.5",
            "vehicle=sdv",
            "start.x=-25",
            "start.y=5.85",
            "start.psi_deg=0",
            "start.speed=1.5",
            "apps.helm.behaviour=nuv_compensation",
            "apps.helm.guard_clearance=0.7",
            "apps.helm.legs=[{points = [[60.0, 5.85]], speed = 1.5, lead = 15.9, lead_to_start = true}]",
            "time_limit=30",
        ],
    )
    result = run_mission(mission, model)
    assert result.outcome == "time_limit"
    helm = result.topic("helm")
    states = {m.step: m for m in result.topic("state")}
    assert all(m.guard_clearance == 0.7 for m in helm)
    step = math.radians(5.0) * mission.dt * mission.apps.helm.period
    for before, m in zip(helm[:-1], helm[1:], strict=True):
        assert abs(m.delta_psi) <= abs(m.guard_limit) + 1e-12
        assert m.guard_saturated == (m.delta_psi != m.delta_psi_commanded)
        assert abs(m.delta_psi - before.delta_psi) <= step + 1e-12 or m.delta_psi == m.guard_limit
        s = states[m.step]
        track = m.psi_d - m.delta_psi
        flown = behaviours.tip_clearance(s.x, s.y, m.psi_d, SDV.length, SDV.diameter)
        straight = behaviours.tip_clearance(s.x, s.y, track, SDV.length, SDV.diameter)
        assert flown >= min(0.7, straight) - 2e-3  # the heading the helm asks for keeps the tips off
    assert any(m.guard_active for m in helm)  # the mission does test the guard
