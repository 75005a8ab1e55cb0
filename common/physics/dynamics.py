"""3-DOF horizontal-plane dynamics: thesis (5.10)/(5.11) integrated with explicit Euler (5.12).

`step` is written once and works on one vehicle (arrays of shape (6,) and (2,)) or on a batch of
N vehicles (shapes (N, 6) and (N, 2)). It uses element-wise numpy operations only (no matrix
products), so each vehicle of a batch sees exactly the arithmetic of a single step.

State columns: [u, v, r, x, y, psi]; input columns: [X_prop, delta_r].
Kinematics in the submarine frame (docs/design.md, "Frames, units and signs"): the water flows
past at -U_sub, so x' = u cos psi - v sin psi - U_sub + u_wave, y' = u sin psi + v cos psi + v_wave,
psi' = r, with the wave orbital velocity of thesis (5.22)/(5.23) (`waves.orbital_velocity`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nearsub.common.physics import waves
from nearsub.common.physics.vehicles import Vehicle

U, V, R, X, Y, PSI = range(6)
X_PROP, DELTA_R = range(2)


def is_batch(value) -> bool:
    """True for an array of vehicles, False for one vehicle's scalar (np.ndim costs 2 us)."""
    return getattr(value, "ndim", 0) > 0


def components(array: np.ndarray, *indices: int) -> list:
    """The named columns of one vehicle's vector as Python floats (numpy scalars cost about 3x
    more per operation), or of a batch as arrays."""
    if array.ndim == 1:
        values = array.tolist()
        return [values[i] for i in indices]
    return [array[..., i] for i in indices]


def columns(*values):
    """Per-vehicle values as the last axis: shape (k,) for one vehicle, (N, k) for a batch.
    np.stack costs about 10 us even for scalars, a fifth of a single-vehicle step, hence the
    cheap path; both give the same numbers."""
    if not is_batch(values[0]):
        return np.array(values, dtype=float)
    return np.stack(values, axis=-1)


def clip(value, lower: float, upper: float):
    """np.clip, without its per-call overhead for one vehicle (same result, NaN included)."""
    if not is_batch(value):
        return min(max(value, lower), upper)
    return np.clip(value, lower, upper)


@dataclass(frozen=True)
class Environment:
    """What surrounds the vehicle: the submarine's speed through the water (0 = earth-fixed) and
    the waves (sea state of thesis table 5.1, operating depth, wave heading in radians)."""

    u_sub: float = 0.0
    sea_state: int = 0
    depth: float = 50.0
    wave_heading: float = 0.0

    def wave_velocity(self, x, y, t: float):
        """(u_wave, v_wave) at the positions, or None in calm water (sea states 0-1)."""
        state = waves.sea_state(self.sea_state)
        if state.amplitude == 0.0:
            return None
        return waves.orbital_velocity(x, y, t, state, self.depth, self.wave_heading, self.u_sub)


INTERACTION_MODES = ("replace", "increment", "thesis")


@dataclass(frozen=True)
class Interaction:
    """Interaction forces near the submarine, from the surrogate (thesis (5.20); docs/design.md,
    "Physics decisions").

    forces: (..., 3) X_s, Y_s, N_s [N, N, N m] in the frame's sign convention; weight: (...,) in
    [0, 1], 1 well inside the surrogate's domain and 0 outside, smooth across the boundary, so no
    force jumps. mode (missions default to "increment", mission.SimSettings):
    - "replace": the surrogate stands for the u- and v-dependent hydrodynamic terms
      X_u|u| u|u|, Y_v|v| v|v| + Y_uv u v, N_v|v| v|v| + N_uv u v; the rate, rigid-body and control
      terms stay (the surrogate is quasi-static, it has no yaw-rate input);
    - "thesis": (5.20) as printed, the surrogate replaces every hydrodynamic and rigid-body term;
    - "increment": (5.11) unchanged plus weight * forces, where forces is the surrogate's
      prediction minus the same model's free-stream value (it tends to zero far away).
    """

    forces: np.ndarray
    weight: np.ndarray
    mode: str = "replace"


def body_forces(state: np.ndarray, inp: np.ndarray, vehicle: Vehicle, interaction: Interaction | None = None):
    """Right-hand side of (5.11) (or (5.20) near the submarine): surge, sway, yaw; shape (..., 3)."""
    u, v, r = components(state, U, V, R)
    thrust, rudder = components(inp, X_PROP, DELTA_R)
    m = vehicle.mass
    uu = u * u
    # abs() rather than np.abs: the same for arrays, and no ufunc overhead for one vehicle.
    flow = columns(  # the u- and v-dependent terms a quasi-static surrogate stands for
        vehicle.X_uu * u * abs(u),
        vehicle.Y_vv * v * abs(v) + vehicle.Y_uv * u * v,
        vehicle.N_vv * v * abs(v) + vehicle.N_uv * u * v,
    )
    rates = columns(  # rate and rigid-body terms
        (vehicle.X_vr + m) * v * r + vehicle.X_rr * r * r,
        vehicle.Y_rr * r * abs(r) + (vehicle.Y_ur - m) * u * r,
        vehicle.N_rr * r * abs(r) + vehicle.N_ur * u * r,
    )
    control = columns(thrust, vehicle.Y_uudr * uu * rudder, vehicle.N_uudr * uu * rudder)
    if interaction is None:
        return flow + rates + control
    w = interaction.weight[..., None]
    if interaction.mode == "replace":
        return (1.0 - w) * flow + w * interaction.forces + rates + control
    if interaction.mode == "thesis":
        return (1.0 - w) * (flow + rates) + w * interaction.forces + control
    if interaction.mode == "increment":
        return flow + rates + control + w * interaction.forces
    raise ValueError(f"interaction mode {interaction.mode!r} is not one of {INTERACTION_MODES}")


def accelerations(forces: np.ndarray, vehicle: Vehicle) -> np.ndarray:
    """Solve the mass matrix of (5.10) for [u', v', r'] in closed form (surge decouples)."""
    m11 = vehicle.mass - vehicle.X_udot
    m22 = vehicle.mass - vehicle.Y_vdot
    m23 = -vehicle.Y_rdot
    m32 = -vehicle.N_vdot
    m33 = vehicle.Izz - vehicle.N_rdot
    det = m22 * m33 - m23 * m32
    f1, f2, f3 = components(forces, 0, 1, 2)
    udot = f1 / m11
    vdot = (m33 * f2 - m23 * f3) / det
    rdot = (m22 * f3 - m32 * f2) / det
    return columns(udot, vdot, rdot)


def derivatives(
    state: np.ndarray,
    inp: np.ndarray,
    vehicle: Vehicle,
    env: Environment,
    t: float = 0.0,
    interaction: Interaction | None = None,
) -> np.ndarray:
    """Time derivative of the full state [u', v', r', x', y', psi'] at time t."""
    acc = accelerations(body_forces(state, inp, vehicle, interaction), vehicle)
    u, v, r, psi = components(state, U, V, R, PSI)
    cos_psi, sin_psi = np.cos(psi), np.sin(psi)
    xdot = u * cos_psi - v * sin_psi - env.u_sub
    ydot = u * sin_psi + v * cos_psi
    wave = env.wave_velocity(state[..., X], state[..., Y], t)
    if wave is not None:
        xdot = xdot + wave[0]
        ydot = ydot + wave[1]
    return np.concatenate([acc, columns(xdot, ydot, r)], axis=-1)


def step(
    state: np.ndarray,
    inp: np.ndarray,
    vehicle: Vehicle,
    env: Environment,
    dt: float,
    method: str = "euler",
    t: float = 0.0,
    interaction: Interaction | None = None,
) -> np.ndarray:
    """Advance the state from time t by dt: explicit Euler (5.12) by default, RK4 on request.
    The interaction forces are evaluated once per step, at the start (held over RK4's stages)."""
    f = interaction
    if method == "euler":
        return state + derivatives(state, inp, vehicle, env, t, f) * dt
    if method == "rk4":
        k1 = derivatives(state, inp, vehicle, env, t, f)
        k2 = derivatives(state + 0.5 * dt * k1, inp, vehicle, env, t + 0.5 * dt, f)
        k3 = derivatives(state + 0.5 * dt * k2, inp, vehicle, env, t + 0.5 * dt, f)
        k4 = derivatives(state + dt * k3, inp, vehicle, env, t + dt, f)
        return state + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    raise ValueError(f"integration method {method!r} is not one of 'euler', 'rk4'")


def wrap_angle(angle):
    """Wrap to [-pi, pi)."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi
