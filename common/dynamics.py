"""3-DOF horizontal-plane dynamics: thesis (5.10)/(5.11) integrated with explicit Euler (5.12).

`step` is written once and works on one vehicle (arrays of shape (6,) and (2,)) or on a batch of
N vehicles (shapes (N, 6) and (N, 2)). It uses element-wise numpy operations only (no matrix
products), so each vehicle of a batch sees exactly the arithmetic of a single step.

State columns: [u, v, r, x, y, psi]; input columns: [X_prop, delta_r].
Kinematics in the submarine frame (SPEC section 2): the water flows past at -U_sub, so
x' = u cos psi - v sin psi - U_sub + u_wave, y' = u sin psi + v cos psi + v_wave, psi' = r,
with the wave orbital velocity of thesis (5.22)/(5.23) (`waves.orbital_velocity`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import waves
from .vehicles import Vehicle

U, V, R, X, Y, PSI = range(6)
X_PROP, DELTA_R = range(2)


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


def body_forces(state: np.ndarray, inp: np.ndarray, vehicle: Vehicle) -> np.ndarray:
    """Right-hand side of (5.11): surge force, sway force and yaw moment, shape (..., 3)."""
    u, v, r = state[..., U], state[..., V], state[..., R]
    thrust, rudder = inp[..., X_PROP], inp[..., DELTA_R]
    m = vehicle.mass
    uu = u * u
    surge = vehicle.X_uu * u * np.abs(u) + (vehicle.X_vr + m) * v * r + vehicle.X_rr * r * r + thrust
    sway = (
        vehicle.Y_vv * v * np.abs(v)
        + vehicle.Y_rr * r * np.abs(r)
        + vehicle.Y_uv * u * v
        + (vehicle.Y_ur - m) * u * r
        + vehicle.Y_uudr * uu * rudder
    )
    yaw = (
        vehicle.N_vv * v * np.abs(v)
        + vehicle.N_rr * r * np.abs(r)
        + vehicle.N_uv * u * v
        + vehicle.N_ur * u * r
        + vehicle.N_uudr * uu * rudder
    )
    return np.stack([surge, sway, yaw], axis=-1)


def accelerations(forces: np.ndarray, vehicle: Vehicle) -> np.ndarray:
    """Solve the mass matrix of (5.10) for [u', v', r'] in closed form (surge decouples)."""
    m11 = vehicle.mass - vehicle.X_udot
    m22 = vehicle.mass - vehicle.Y_vdot
    m23 = -vehicle.Y_rdot
    m32 = -vehicle.N_vdot
    m33 = vehicle.Izz - vehicle.N_rdot
    det = m22 * m33 - m23 * m32
    f1, f2, f3 = forces[..., 0], forces[..., 1], forces[..., 2]
    udot = f1 / m11
    vdot = (m33 * f2 - m23 * f3) / det
    rdot = (m22 * f3 - m32 * f2) / det
    return np.stack([udot, vdot, rdot], axis=-1)


def derivatives(state: np.ndarray, inp: np.ndarray, vehicle: Vehicle, env: Environment, t: float = 0.0) -> np.ndarray:
    """Time derivative of the full state [u', v', r', x', y', psi'] at time t."""
    acc = accelerations(body_forces(state, inp, vehicle), vehicle)
    u, v, r, psi = state[..., U], state[..., V], state[..., R], state[..., PSI]
    cos_psi, sin_psi = np.cos(psi), np.sin(psi)
    xdot = u * cos_psi - v * sin_psi - env.u_sub
    ydot = u * sin_psi + v * cos_psi
    wave = env.wave_velocity(state[..., X], state[..., Y], t)
    if wave is not None:
        xdot = xdot + wave[0]
        ydot = ydot + wave[1]
    return np.concatenate([acc, np.stack([xdot, ydot, r], axis=-1)], axis=-1)


def step(
    state: np.ndarray,
    inp: np.ndarray,
    vehicle: Vehicle,
    env: Environment,
    dt: float,
    method: str = "euler",
    t: float = 0.0,
) -> np.ndarray:
    """Advance the state from time t by dt: explicit Euler (5.12) by default, RK4 on request."""
    if method == "euler":
        return state + derivatives(state, inp, vehicle, env, t) * dt
    if method == "rk4":
        k1 = derivatives(state, inp, vehicle, env, t)
        k2 = derivatives(state + 0.5 * dt * k1, inp, vehicle, env, t + 0.5 * dt)
        k3 = derivatives(state + 0.5 * dt * k2, inp, vehicle, env, t + 0.5 * dt)
        k4 = derivatives(state + dt * k3, inp, vehicle, env, t + dt)
        return state + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    raise ValueError(f"integration method {method!r} is not one of 'euler', 'rk4'")


def wrap_angle(angle):
    """Wrap to [-pi, pi)."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi
