"""Benchmark problems of thesis section 2.4-2.5, behind the simulator protocol used by NMMF.

A `Problem` carries what an active-learning campaign needs from a simulator: the design
domain, an optional feasibility constraint, and the LF and HF evaluators. Evaluators map
X (n, d) to Y (n, m): one column per output, even for scalar problems, so single- and
multi-output problems share one code path. The real surrogate training (chapter 4) plugs in
through the same fields, or evaluates requests externally (see `nearsub.common.learning.active`).

Problems: Park (2.19, 2.20), Borehole (2.24-2.26), the 3-DOF trebuchet (2.21-2.23) with a 2-DOF
LF, the subsonic wing lift-curve slope (2.27-2.29), and the three-output Park1/Park2/Colville
set (2.33-2.35, single fidelity as in figure 2-10).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

__all__ = [
    "Problem",
    "PROBLEMS",
    "get_problem",
    "park_hf",
    "park_lf",
    "borehole_hf",
    "borehole_lf",
    "trebuchet_range",
    "wing_hf",
    "wing_lf",
    "datcom_slope_ratio",
    "park1",
    "park2",
    "colville",
]

Evaluator = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Problem:
    """A simulator as active learning sees it: domain, constraint and fidelity evaluators.

    bounds: (d, 2) box of the design inputs. constraint: c(X) -> (n,) or (n, k), feasible
    where every entry is >= 0 (None: the whole box is feasible). hf, lf: X (n, d) -> Y (n, m);
    lf is None for single-fidelity problems.
    """

    name: str
    bounds: np.ndarray
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    hf: Evaluator
    lf: Evaluator | None = None
    constraint: Evaluator | None = None
    description: str = ""

    @property
    def d(self) -> int:
        return self.bounds.shape[0]

    @property
    def n_outputs(self) -> int:
        return len(self.output_names)

    def feasible(self, X: np.ndarray) -> np.ndarray:
        """Boolean mask (n,) of rows inside the box and satisfying the constraint."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        ok = np.all((X >= self.bounds[:, 0]) & (X <= self.bounds[:, 1]), axis=1)
        if self.constraint is not None:
            c = np.asarray(self.constraint(X), dtype=float).reshape(X.shape[0], -1)
            ok &= np.all(c >= 0.0, axis=1)
        return ok


def _columns(*cols: np.ndarray) -> np.ndarray:
    return np.column_stack(cols)


# --------------------------------------------------------------------------- Park
def park_hf(X: np.ndarray) -> np.ndarray:
    """Park (1991) function 2, thesis (2.19): 2/3 exp(x1 + x2) - x4 sin(x3) + x3."""
    X = np.atleast_2d(X)
    x1, x2, x3, x4 = X.T
    return 2.0 / 3.0 * np.exp(x1 + x2) - x4 * np.sin(x3) + x3


def park_lf(X: np.ndarray) -> np.ndarray:
    """Xiong's LF for Park, thesis (2.20): 1.2 y_HF - 1 (affine in the HF; learning/mfgp.py explains why
    that matters)."""
    return 1.2 * park_hf(X) - 1.0


# ----------------------------------------------------------------------- Borehole
def _borehole(X: np.ndarray, numerator: float, offset: float) -> np.ndarray:
    X = np.atleast_2d(X)
    rw, r, Tu, Hu, Tl, Hl, L, Kw = X.T
    log_ratio = np.log(r / rw)
    bracket = offset + 2.0 * L * Tu / (log_ratio * rw**2 * Kw) + Tu / Tl
    return numerator * Tu * (Hu - Hl) / (log_ratio * bracket)


def borehole_hf(X: np.ndarray) -> np.ndarray:
    """Harper-Gupta borehole flow rate [m^3/yr], thesis (2.24)."""
    return _borehole(X, 2.0 * math.pi, 1.0)


def borehole_lf(X: np.ndarray) -> np.ndarray:
    """Xiong's borehole LF, thesis (2.25): 5 instead of 2 pi, 1.5 instead of 1."""
    return _borehole(X, 5.0, 1.5)


# ---------------------------------------------------------------------- Trebuchet
# Constants the thesis leaves as "m_arm, l_arm, I_arm = f(l1, l2, constants)" (2.21). The arm
# is a uniform beam of linear density _ARM_DENSITY from the counterweight end (l1) to the sling
# end (l2): m_arm = rho (l1 + l2), CG at l_arm = (l2 - l1)/2 on the sling side, I_arm about its
# CG = m_arm (l1 + l2)^2 / 12. A light arm and projectile keep every design in (2.23) able to
# throw (even m1 = 40 kg on a 0.5 m short arm outweighs the arm's moment, 20 > 12 kg m).
_G = 9.81  # m/s^2
_PROJECTILE_MASS = 1.0  # m2 [kg]
_ARM_DENSITY = 1.0  # [kg/m]
# Launch hook angle beta of section 2.4.2 (its value is not printed): release when the
# projectile's velocity, moving forward, points 45 deg above the horizontal (VirtualTrebuchet's
# default, also the drag-free optimum), so every design throws forward.
_RELEASE_ANGLE = math.radians(45.0)
# Smallest l2 - h0 [m]: at h0 = l2 the arm starts vertical (theta0 = pi/2 in (2.22)), an
# equilibrium that never throws, and near it the start stalls. Excludes 0.25 % of the box.
_ARM_CLEARANCE = 0.05
_T_END = 20.0  # s; generous: the slowest designs release in about 3 s
_ODE_TOL = 1e-9  # smooth range vs inputs, so GP fits are not polluted by integration noise
_MAX_PHASES = 40


class _Trebuchet:
    """Equations of motion (2.21) of the hinged-counterweight trebuchet, or its 2-DOF LF.

    Coordinates are the absolute angles of figure 2-6: theta (arm, from the horizontal, short arm
    end at l1 (cos theta, sin theta), sling end at -l2 (cos theta, sin theta)), phi (hanger of the
    counterweight) and psi (sling). The pivot is at height h0, so the ground is y = -h0.

    Two corrections to (2.21) as printed, both derived from the Lagrangian and confirmed by
    energy conservation (tests): the printed cos(theta - phi) in M13 and sin(theta - phi) in the
    psi terms of rows 1 and 3 are cos/sin(theta - psi), and row 3's theta-dot^2 term has a minus
    sign: -m2 l2 l3 theta_dot^2 sin(theta - psi).
    The LF (rigid counterweight at the short-arm tip) drops phi: no l4, no row/column 2.
    """

    def __init__(self, x: np.ndarray, hinged: bool):
        self.l1, self.l2, self.l3, self.l4, self.h0, self.m1 = (float(v) for v in x)
        self.hinged = hinged
        self.n = 3 if hinged else 2
        self.m2 = _PROJECTILE_MASS
        self.m_arm = _ARM_DENSITY * (self.l1 + self.l2)
        self.l_arm = 0.5 * (self.l2 - self.l1)
        self.I_arm = self.m_arm * (self.l1 + self.l2) ** 2 / 12.0

    def initial_state(self) -> np.ndarray:
        """(2.22): sling end on the ground, counterweight hanging, sling flat, at rest."""
        theta0 = math.asin(self.h0 / self.l2)
        q0 = [theta0, -math.pi / 2, 0.0] if self.hinged else [theta0, 0.0]
        return np.array(q0 + [0.0] * self.n)

    def _split(self, s):
        th, ps = s[0], s[self.n - 1]
        thd, psd = s[self.n], s[2 * self.n - 1]
        return th, ps, thd, psd

    def mass_force(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mass matrix M(q) and right-hand side f(q, q') of (2.21): M q'' = f."""
        l1, l2, l3, l4, m1, m2 = self.l1, self.l2, self.l3, self.l4, self.m1, self.m2
        th, ps, thd, psd = self._split(s)
        cp, sp = math.cos(th - ps), math.sin(th - ps)
        M11 = m1 * l1**2 + m2 * l2**2 + self.m_arm * self.l_arm**2 + self.I_arm
        M13 = -m2 * l2 * l3 * cp
        M33 = m2 * l3**2
        gravity = -(m1 * l1 - m2 * l2 - self.m_arm * self.l_arm) * _G * math.cos(th)
        f1 = m2 * l2 * l3 * psd**2 * sp + gravity
        f3 = -m2 * l2 * l3 * thd**2 * sp - m2 * l3 * _G * math.cos(ps)
        if not self.hinged:
            return np.array([[M11, M13], [M13, M33]]), np.array([f1, f3])
        ph, phd = s[1], s[4]
        cf, sf = math.cos(th - ph), math.sin(th - ph)
        M12 = m1 * l1 * l4 * cf
        M = np.array([[M11, M12, M13], [M12, m1 * l4**2, 0.0], [M13, 0.0, M33]])
        f1 -= m1 * l1 * l4 * phd**2 * sf
        f2 = m1 * l1 * l4 * thd**2 * sf - m1 * l4 * _G * math.cos(ph)
        return M, np.array([f1, f2, f3])

    def projectile(self, s: np.ndarray) -> tuple[float, float, float, float]:
        """Projectile position and velocity (x, y, vx, vy), pivot at the origin."""
        th, ps, thd, psd = self._split(s)
        x = -self.l2 * math.cos(th) + self.l3 * math.cos(ps)
        y = -self.l2 * math.sin(th) + self.l3 * math.sin(ps)
        vx = self.l2 * thd * math.sin(th) - self.l3 * psd * math.sin(ps)
        vy = -self.l2 * thd * math.cos(th) + self.l3 * psd * math.cos(ps)
        return x, y, vx, vy

    def _ground_jacobian(self, s):
        """J = d y_proj / dq and J' q' (the constraint acceleration term)."""
        th, ps, thd, psd = self._split(s)
        J = np.zeros(self.n)
        J[0], J[-1] = -self.l2 * math.cos(th), self.l3 * math.cos(ps)
        Jdqd = self.l2 * math.sin(th) * thd**2 - self.l3 * math.sin(ps) * psd**2
        return J, Jdqd

    def ground_solve(self, s: np.ndarray) -> tuple[np.ndarray, float]:
        """Accelerations and normal force while the projectile slides on the ground."""
        M, f = self.mass_force(s)
        J, Jdqd = self._ground_jacobian(s)
        n = self.n
        A = np.zeros((n + 1, n + 1))
        A[:n, :n], A[:n, n], A[n, :n] = M, -J, J
        sol = np.linalg.solve(A, np.append(f, -Jdqd))
        return sol[:n], float(sol[n])

    def impact(self, s: np.ndarray) -> np.ndarray:
        """Plastic touchdown: cancel the downward projectile velocity (least kinetic change)."""
        M, _ = self.mass_force(s)
        J, _ = self._ground_jacobian(s)
        qd = s[self.n :]
        MinvJ = np.linalg.solve(M, J)
        return np.concatenate([s[: self.n], qd - MinvJ * (J @ qd) / (J @ MinvJ)])

    def energy(self, s: np.ndarray) -> float:
        """Kinetic plus potential energy: conserved between impacts (checks the EOM)."""
        M, _ = self.mass_force(s)
        qd = s[self.n :]
        th, ps = s[0], s[self.n - 1]
        y_cw = self.l1 * math.sin(th) + (self.l4 * math.sin(s[1]) if self.hinged else 0.0)
        y_p = -self.l2 * math.sin(th) + self.l3 * math.sin(ps)
        V = _G * (self.m1 * y_cw + self.m2 * y_p - self.m_arm * self.l_arm * math.sin(th))
        return 0.5 * float(qd @ M @ qd) + V

    def throw(self) -> float:
        """Range [m] from the pivot: ground slide, sling swing (touchdowns), release, flight."""
        n = self.n
        sin_b, cos_b = math.sin(_RELEASE_ANGLE), math.cos(_RELEASE_ANGLE)

        def ground_rhs(t, s):
            return np.concatenate([s[n:], self.ground_solve(s)[0]])

        def lift_off(t, s):
            return self.ground_solve(s)[1]

        def air_rhs(t, s):
            M, f = self.mass_force(s)
            return np.concatenate([s[n:], np.linalg.solve(M, f)])

        def release(t, s):
            _, _, vx, vy = self.projectile(s)
            return vy * cos_b - vx * sin_b  # = |v| sin(angle - beta): falls through 0 at beta

        def touchdown(t, s):
            return self.projectile(s)[1] + self.h0

        for event, direction in ((lift_off, -1), (release, -1), (touchdown, -1)):
            event.terminal, event.direction = True, direction

        s, t, on_ground = self.initial_state(), 0.0, True
        for _ in range(_MAX_PHASES):
            if on_ground:
                r = solve_ivp(ground_rhs, (t, _T_END), s, events=lift_off, rtol=_ODE_TOL, atol=_ODE_TOL)
            else:
                r = solve_ivp(
                    air_rhs,
                    (t, _T_END),
                    s,
                    events=(release, touchdown),
                    rtol=_ODE_TOL,
                    atol=_ODE_TOL,
                )
            if r.status != 1:
                break
            s, t = r.y[:, -1], float(r.t[-1])
            if on_ground:
                on_ground = False
            elif r.t_events[1].size:  # touchdown before release
                s = self.impact(s)
                on_ground = self.ground_solve(s)[1] > 0.0
            else:
                x, y, vx, vy = self.projectile(s)
                if vx > 0.0:  # the 45 deg crossing while moving forward
                    t_flight = (vy + math.sqrt(vy**2 + 2.0 * _G * (y + self.h0))) / _G
                    return x + vx * t_flight
                # a backward-moving crossing (at 225 deg): step past it and keep swinging
                r = solve_ivp(air_rhs, (t, t + 1e-6), s, rtol=_ODE_TOL, atol=_ODE_TOL)
                s, t = r.y[:, -1], float(r.t[-1])
        raise RuntimeError(f"trebuchet design {self.__dict__} did not release")


def trebuchet_range(X: np.ndarray, hinged: bool = True) -> np.ndarray:
    """Projectile range [m] for designs X (n, 6) = (l1, l2, l3, l4, h0, m1) of (2.23).

    hinged=True is the 3-DOF HF (2.21); False is the 2-DOF rigid-counterweight LF (l4 unused).
    """
    X = np.atleast_2d(np.asarray(X, dtype=float))
    return np.array([_Trebuchet(x, hinged).throw() for x in X])


def _trebuchet_clearance(X: np.ndarray) -> np.ndarray:
    """Feasible where l2 - h0 >= 5 cm: the arm must start tilted, not vertical (2.22)."""
    X = np.atleast_2d(X)
    return X[:, 1] - X[:, 4] - _ARM_CLEARANCE


# --------------------------------------------------------------------------- Wing
def _half_chord_sweep(A, taper, sweep_c4):
    """Lambda_c/2 from Lambda_c/4 for a straight-tapered wing, (2.28)."""
    return np.arctan(np.tan(sweep_c4) - (1.0 / A) * (1.0 - taper) / (1.0 + taper))


def wing_hf(X: np.ndarray) -> np.ndarray:
    """Helmbold/DATCOM lift-curve slope [1/rad], thesis (2.28) as printed.

    Inputs (2.29): c_l_alpha [1/deg], A, taper, Lambda_c/4 [deg], Mach, t/c (t/c unused).
    """
    X = np.atleast_2d(X)
    cla_deg, A, taper, sweep_deg, mach, _ = X.T
    beta = np.sqrt(1.0 - mach**2)
    kappa = np.degrees(cla_deg) / (2.0 * np.pi)  # section slope per rad over 2 pi
    tan_c2 = np.tan(_half_chord_sweep(A, taper, np.radians(sweep_deg)))
    root = np.sqrt(A**2 * beta**2 / kappa**2 * (1.0 + tan_c2**2 / beta**2) + 4.0)
    return 2.0 * np.pi * A / (2.0 + root)


# DATCOM figure 4.1.3.2-50a (C_L_alpha / (C_L_alpha)_theory against the planform parameter
# P = (1/(3 + A)) ((1 - lambda)/(1 + 2 lambda))^2 and t/c) is not public, so it cannot be
# digitised here. Stand-in: a bilinear surface with the chart's assumed trends (the ratio is 1
# for a vanishingly thin wing and falls with thickness and with P). Over (2.29) P lies in
# [0.011, 0.041] and t/c in [0.08, 0.20], so the ratio spans about 0.77-0.92.
_RATIO_PER_THICKNESS = 0.75
_RATIO_PER_PLANFORM = 2.0


def datcom_slope_ratio(planform: np.ndarray, thickness: np.ndarray) -> np.ndarray:
    """Approximation of DATCOM figure 4.1.3.2-50a (see the comment above: not a digitisation)."""
    return 1.0 - _RATIO_PER_THICKNESS * thickness - _RATIO_PER_PLANFORM * planform


def wing_lf(X: np.ndarray) -> np.ndarray:
    """Low-aspect-ratio DATCOM lift-curve slope [1/rad], (2.27); Mach and c_l_alpha unused."""
    X = np.atleast_2d(X)
    _, A, taper, sweep_deg, _, tc = X.T
    tan_le = np.tan(np.radians(sweep_deg)) + (1.0 / A) * (1.0 - taper) / (1.0 + taper)
    theory = 8.0 * np.arctan(np.pi * A / (16.0 + np.pi * A / (1.0 + 2.0 * taper * tan_le)))
    planform = (1.0 / (3.0 + A)) * ((1.0 - taper) / (1.0 + 2.0 * taper)) ** 2
    return theory * datcom_slope_ratio(planform, tc)


# ------------------------------------------------------------ Multi-output (2.33-2.35)
def park1(X: np.ndarray) -> np.ndarray:
    """Thesis (2.33): the same function as the Park HF (2.19)."""
    return park_hf(X)


def park2(X: np.ndarray) -> np.ndarray:
    """Thesis (2.34), Park (1991) function 1: note (x2 + x3^2), not emukit's (x2 + x3)."""
    X = np.atleast_2d(X)
    x1, x2, x3, x4 = X.T
    root = np.sqrt(1.0 + (x2 + x3**2) * x4 / x1**2)
    return x1 / 2.0 * (root - 1.0) + (x1 + 3.0 * x4) * np.exp(1.0 + np.sin(x3))


def colville(X: np.ndarray) -> np.ndarray:
    """Thesis (2.35), the Colville function (zero at (1, 1, 1, 1), a corner of the domain)."""
    X = np.atleast_2d(X)
    x1, x2, x3, x4 = X.T
    return (
        100.0 * (x1**2 - x2) ** 2
        + (x1 - 1.0) ** 2
        + (x3 - 1.0) ** 2
        + 90.0 * (x3**2 - x4) ** 2
        + 10.1 * ((x2 - 1.0) ** 2 + (x4 - 1.0) ** 2)
        + 19.8 * (x2 - 1.0) * (x4 - 1.0)
    )


# ---------------------------------------------------------------------- registry
def _park() -> Problem:
    return Problem(
        name="park",
        bounds=np.array([[0.0, 1.0]] * 4),
        input_names=("x1", "x2", "x3", "x4"),
        output_names=("y",),
        hf=lambda X: _columns(park_hf(X)),
        lf=lambda X: _columns(park_lf(X)),
        description="Park (1991) function 2, LF = 1.2 HF - 1 (2.19, 2.20)",
    )


def _borehole_problem() -> Problem:
    return Problem(
        name="borehole",
        bounds=np.array(
            [
                [0.05, 0.15],
                [100.0, 50000.0],
                [63070.0, 115600.0],
                [990.0, 1110.0],
                [63.1, 116.0],
                [700.0, 820.0],
                [1120.0, 1680.0],
                [9855.0, 12045.0],
            ]
        ),
        input_names=("r_w", "r", "T_u", "H_u", "T_l", "H_l", "L", "K_w"),
        output_names=("Q",),
        hf=lambda X: _columns(borehole_hf(X)),
        lf=lambda X: _columns(borehole_lf(X)),
        description="Borehole flow rate, Xiong LF (2.24-2.26)",
    )


def _trebuchet_problem() -> Problem:
    return Problem(
        name="trebuchet",
        bounds=np.array([[0.5, 1.5], [3.5, 4.5], [3.0, 4.0], [0.1, 1.0], [3.0, 3.5], [40.0, 400.0]]),
        input_names=("l1", "l2", "l3", "l4", "h0", "m1"),
        output_names=("range",),
        hf=lambda X: _columns(trebuchet_range(X, hinged=True)),
        lf=lambda X: _columns(trebuchet_range(X, hinged=False)),
        constraint=_trebuchet_clearance,
        description="Trebuchet range: 3-DOF hinged counterweight HF, 2-DOF rigid LF (2.21-2.23)",
    )


def _wing_problem() -> Problem:
    return Problem(
        name="wing",
        bounds=np.array([[0.11, 0.12], [5.0, 20.0], [0.2, 0.25], [15.0, 35.0], [0.2, 0.8], [0.08, 0.2]]),
        input_names=("c_l_alpha", "A", "taper", "sweep_c4", "Mach", "t_c"),
        output_names=("C_L_alpha",),
        hf=lambda X: _columns(wing_hf(X)),
        lf=lambda X: _columns(wing_lf(X)),
        description="Wing lift-curve slope: Helmbold HF, DATCOM low-AR LF (approximated chart)",
    )


def _multi_output_problem() -> Problem:
    return Problem(
        name="multi-output",
        bounds=np.array([[0.1, 1.0]] * 4),
        input_names=("x1", "x2", "x3", "x4"),
        output_names=("park1", "park2", "colville"),
        hf=lambda X: _columns(park1(X), park2(X), colville(X)),
        description="Park1, Park2, Colville on [0.1, 1]^4 (2.33-2.35), single fidelity",
    )


PROBLEMS: dict[str, Callable[[], Problem]] = {
    "park": _park,
    "borehole": _borehole_problem,
    "trebuchet": _trebuchet_problem,
    "wing": _wing_problem,
    "multi-output": _multi_output_problem,
}


def get_problem(name: str) -> Problem:
    """The benchmark problem called `name` (one of PROBLEMS)."""
    try:
        return PROBLEMS[name]()
    except KeyError:
        raise LookupError(f"unknown problem {name!r}; choose from {sorted(PROBLEMS)}") from None
