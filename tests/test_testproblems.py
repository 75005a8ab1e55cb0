"""Benchmark problems against values computed by hand from the printed thesis equations."""

import math

import numpy as np
import pytest

from nearsub.common.learning import testproblems as tp
from nearsub.common.learning.testproblems import get_problem

# Reference values: scalar `math` evaluations of the printed equations, written out by hand
# (e.g. Park (2.19) at x = 0.5: 2/3 e - 0.5 sin 0.5 + 0.5 = 1.81219 - 0.23971 + 0.5).
PARK = [
    ((0.5, 0.5, 0.5, 0.5), 2.072475116337262),
    ((0.1, 0.9, 0.3, 0.7), 1.9053237409764259),
    ((1.0, 1.0, 1.0, 1.0), 5.0845664144792035),
]
# (2.34) with (x2 + x3^2): emukit's (x2 + x3) would give 16.31 at the first point.
PARK2 = [((0.5, 0.2, 0.7, 0.9), 16.782903533530167), ((0.1, 0.1, 0.1, 0.1), 1.2239231323618227)]
# (2.35) at the first point: 0.25 + 0.25 + 0.09 + 15.129 + 6.565 + 1.584 = 23.868.
COLVILLE = [((0.5, 0.2, 0.7, 0.9), 23.868), ((1.0, 1.0, 1.0, 1.0), 0.0)]
# (2.24), (2.25) at the centre and at the lower corner of (2.26).
BOREHOLE = [
    ((0.1, 25050, 89335, 1050, 89.55, 760, 1400, 10950), 70.87291263681897, 56.398719259575394),
    ((0.05, 100, 63070, 990, 63.1, 700, 1120, 9855), 20.01478331243087, 15.92724795335779),
]
# (2.28) and (2.27) with the documented chart stand-in 1 - 0.75 t/c - 2 P.
WING = [
    ((0.115, 10, 0.2, 25, 0.5, 0.12), 5.554203566485238, 4.425491416749788),
    ((0.11, 20, 0.25, 35, 0.8, 0.2), 6.268518648627732, 5.246819694658742),
]


@pytest.mark.parametrize(("x", "y"), PARK)
def test_park_matches_printed_equations(x, y):
    X = np.array([x])
    assert tp.park_hf(X)[0] == pytest.approx(y, rel=1e-14)
    assert tp.park_lf(X)[0] == pytest.approx(1.2 * y - 1.0, rel=1e-14)  # (2.20)
    assert get_problem("park").hf(X).shape == (1, 1)


@pytest.mark.parametrize(("x", "y"), PARK2)
def test_park2_uses_x3_squared(x, y):
    assert tp.park2(np.array([x]))[0] == pytest.approx(y, rel=1e-14)


@pytest.mark.parametrize(("x", "y"), COLVILLE)
def test_colville(x, y):
    assert tp.colville(np.array([x]))[0] == pytest.approx(y, rel=1e-14, abs=1e-12)


def test_multi_output_stacks_park1_park2_colville():
    X = np.array([PARK2[0][0]])
    Y = get_problem("multi-output").hf(X)
    np.testing.assert_allclose(Y, [[tp.park_hf(X)[0], PARK2[0][1], COLVILLE[0][1]]], rtol=1e-14)
    assert get_problem("multi-output").lf is None  # figure 2-10 is single fidelity


@pytest.mark.parametrize(("x", "hf", "lf"), BOREHOLE)
def test_borehole(x, hf, lf):
    X = np.array([x], dtype=float)
    assert tp.borehole_hf(X)[0] == pytest.approx(hf, rel=1e-13)
    assert tp.borehole_lf(X)[0] == pytest.approx(lf, rel=1e-13)


def test_borehole_lf_is_nearly_proportional():
    """T_u/T_l dominates the bracket, so LF/HF ~ 5/(2 pi) (1+A+B)/(1.5+A+B) ~ 0.796 everywhere."""
    p = get_problem("borehole")
    rng = np.random.default_rng(0)
    X = p.bounds[:, 0] + rng.uniform(size=(500, 8)) * np.ptp(p.bounds, axis=1)
    ratio = p.lf(X)[:, 0] / p.hf(X)[:, 0]
    assert 0.79 < ratio.min() and ratio.max() < 0.80


@pytest.mark.parametrize(("x", "hf", "lf"), WING)
def test_wing(x, hf, lf):
    X = np.array([x], dtype=float)
    assert tp.wing_hf(X)[0] == pytest.approx(hf, rel=1e-13)
    assert tp.wing_lf(X)[0] == pytest.approx(lf, rel=1e-13)


def test_wing_hf_reduces_to_lifting_line_helmbold():
    """kappa = 1, M = 0, Lambda_c/2 = 0 gives 2 pi A / (2 + sqrt(A^2 + 4))."""
    A, taper = 8.0, 0.2
    sweep_c4 = math.degrees(math.atan((1.0 - taper) / (1.0 + taper) / A))  # Lambda_c/2 = 0
    cla_per_deg = 2 * math.pi * math.pi / 180.0  # c_l_alpha = 2 pi per rad
    X = np.array([[cla_per_deg, A, taper, sweep_c4, 0.0, 0.1]])
    expected = 2 * math.pi * A / (2 + math.sqrt(A**2 + 4))
    assert tp.wing_hf(X)[0] == pytest.approx(expected, rel=1e-12)


def _lagrangian_eom(tr, s):
    """M and f from the positions of the masses alone (independent of the hand-derived (2.21)):
    M = sum m J^T J (+ the arm's rotary inertia), f = dT/dq - dV/dq - (dM/dq . qd) qd, with the
    Jacobians J and the q-derivatives by central differences."""
    n = tr.n
    eye = np.eye(n)

    def positions(q):
        th, ps = q[0], q[-1]
        cw = np.array([tr.l1 * math.cos(th), tr.l1 * math.sin(th)])
        if tr.hinged:
            cw += tr.l4 * np.array([math.cos(q[1]), math.sin(q[1])])
        proj = tr.l3 * np.array([math.cos(ps), math.sin(ps)]) - tr.l2 * np.array([math.cos(th), math.sin(th)])
        return cw, proj

    def mass(q, h=1e-6):
        J = [
            np.column_stack([(positions(q + h * e)[i] - positions(q - h * e)[i]) / (2 * h) for e in eye])
            for i in (0, 1)
        ]
        M = tr.m1 * J[0].T @ J[0] + tr.m2 * J[1].T @ J[1]
        M[0, 0] += tr.m_arm * tr.l_arm**2 + tr.I_arm
        return M

    def potential(q):
        cw, proj = positions(q)
        return tp._G * (tr.m1 * cw[1] + tr.m2 * proj[1] - tr.m_arm * tr.l_arm * math.sin(q[0]))

    q, qd = s[:n], s[n:]
    dM = [(mass(q + 1e-4 * e) - mass(q - 1e-4 * e)) / 2e-4 for e in eye]
    dT = np.array([0.5 * qd @ dMk @ qd for dMk in dM])
    dV = np.array([(potential(q + 1e-6 * e) - potential(q - 1e-6 * e)) / 2e-6 for e in eye])
    coriolis = sum(dMk * qd[k] for k, dMk in enumerate(dM)) @ qd
    return mass(q), dT - dV - coriolis


@pytest.mark.parametrize("hinged", [True, False])
def test_trebuchet_eom_match_lagrangian(hinged):
    tr = tp._Trebuchet(np.array([1.1, 4.2, 3.4, 0.6, 3.2, 150.0]), hinged)
    rng = np.random.default_rng(1)
    for _ in range(3):
        s = np.concatenate([rng.uniform(-3, 3, tr.n), rng.uniform(-4, 4, tr.n)])
        M, f = tr.mass_force(s)
        M_ref, f_ref = _lagrangian_eom(tr, s)
        np.testing.assert_allclose(M, M_ref, rtol=1e-7, atol=1e-7 * np.abs(M).max())
        np.testing.assert_allclose(f, f_ref, rtol=1e-6, atol=1e-6 * np.abs(f_ref).max())
        if hinged:  # the printed (2.21) row 3 has +m2 l2 l3 thd^2 sin(.): that breaks the EOM
            th, ps, thd = s[0], s[2], s[3]
            printed = f[2] + 2 * tr.m2 * tr.l2 * tr.l3 * thd**2 * math.sin(th - ps)
            assert abs(printed - f_ref[2]) > 1e3 * 1e-6 * np.abs(f_ref).max()  # 1000x the tolerance


@pytest.mark.parametrize("hinged", [True, False])
def test_trebuchet_conserves_energy_until_release(hinged):
    from scipy.integrate import solve_ivp

    tr = tp._Trebuchet(np.array([1.0, 4.0, 3.5, 0.5, 3.25, 200.0]), hinged)
    s0 = tr.initial_state()
    n = tr.n
    rhs = lambda t, s: np.concatenate([s[n:], tr.ground_solve(s)[0]])  # noqa: E731
    r = solve_ivp(rhs, (0.0, 0.15), s0, rtol=1e-10, atol=1e-10)
    assert tr.ground_solve(r.y[:, -1])[1] > 0.0  # still sliding
    assert tr.energy(r.y[:, -1]) == pytest.approx(tr.energy(s0), rel=1e-8)


def test_trebuchet_initial_conditions_and_range():
    x = np.array([1.0, 4.0, 3.5, 0.5, 3.25, 200.0])
    s0 = tp._Trebuchet(x, True).initial_state()
    np.testing.assert_allclose(s0[:3], [math.asin(3.25 / 4.0), -math.pi / 2, 0.0])  # (2.22)
    px, py, _, _ = tp._Trebuchet(x, True).projectile(s0)
    assert py == pytest.approx(-3.25)  # the projectile starts on the ground
    p = get_problem("trebuchet")
    rng = np.random.default_rng(2)
    X = p.bounds[:, 0] + rng.uniform(size=(6, 6)) * np.ptp(p.bounds, axis=1)
    X = X[p.feasible(X)]
    hf, lf = p.hf(X)[:, 0], p.lf(X)[:, 0]
    assert np.all(np.isfinite(hf)) and np.all(hf > 0) and np.all(lf > 0)
    x_far = x.copy()
    x_far[3] = 0.1  # the LF ignores l4 (rigid counterweight)
    assert p.lf(x_far[None])[0, 0] == p.lf(x[None])[0, 0]


def test_trebuchet_constraint_excludes_vertical_arm():
    p = get_problem("trebuchet")
    x = np.array([[1.0, 3.5, 3.5, 0.5, 3.5, 200.0], [1.0, 3.6, 3.5, 0.5, 3.5, 200.0]])
    np.testing.assert_array_equal(p.feasible(x), [False, True])


def test_feasible_checks_bounds():
    p = get_problem("park")
    np.testing.assert_array_equal(p.feasible(np.array([[0.5] * 4, [1.1, 0.5, 0.5, 0.5]])), [True, False])
    with pytest.raises(LookupError):
        get_problem("nope")
