"""Compiled kernel of the helm's hull-avoidance prediction (`helm.predicted_clearance`): each
candidate command flown forward from the same state with the vehicle's own (5.10)-(5.12) and the
positional PID (`control.pid_step`), candidate by candidate, step by step, in scalars.

The arithmetic is `dynamics.step` (Euler) and `control.pid_step` ("positional") written out for
one vehicle, term by term in their order (no fastmath); only the C library's cos and sin differ
from numpy's, so the poses agree with the numpy functions to rounding (tests/test_helm_kernel.py
states the tolerance for every library vehicle and interaction mode). Numpy on (32,) arrays cost
about 10 ms a helm iteration here, 60 % of the in-process time of four UUVs beside the submarine.
Imported on first use (`helm._prediction_kernel`); compiled once per install into numba's cache.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Interaction modes as the kernel reads them (`dynamics.INTERACTION_MODES`, and none held).
MODE_CODES = {None: 0, "increment": 1, "replace": 2, "thesis": 3}

# Vehicle coefficients in the order `vehicle_row` packs them.
COEFFICIENTS = (
    "mass", "Izz", "X_udot", "Y_vdot", "Y_rdot", "N_vdot", "N_rdot", "X_uu", "X_vr", "X_rr", "Y_vv",
    "Y_rr", "Y_uv", "Y_ur", "N_vv", "N_rr", "N_uv", "N_ur", "Y_uudr", "N_uudr", "max_thrust", "max_rudder",
)  # fmt: skip


def vehicle_row(vehicle) -> np.ndarray:
    """The vehicle's coefficients (COEFFICIENTS) and its PID gains (heading kp, kd, ki, integral
    limit, then the same for speed) as one float array."""
    gains = [
        getattr(loop, name)
        for loop in (vehicle.pid.heading, vehicle.pid.speed)
        for name in ("kp", "kd", "ki", "integral_limit")
    ]
    return np.array([getattr(vehicle, name) for name in COEFFICIENTS] + gains, dtype=float)


@njit(cache=True)
def _clip(value, lower, upper):
    """np.clip for one value, NaN kept (numba's min and max do not promise it)."""
    if value < lower:
        return lower
    if value > upper:
        return upper
    return value


@njit(cache=True)
def flown_poses(state, psi_c, u_c, c, forces, weight, mode, u_sub, dt, steps, check, poses):
    """Fly every candidate (psi_c[m], u_c[m]) from `state` for `steps` Euler steps of dt with the
    interaction `forces` (3,) held at `weight` in `mode` (MODE_CODES); at each check step (every
    `check`-th and the last) write x, y, psi and 1.0 if the whole state is finite (else 0.0) into
    poses[m, j]."""
    (m_, izz, x_udot, y_vdot, y_rdot, n_vdot, n_rdot, x_uu, x_vr, x_rr, y_vv, y_rr, y_uv, y_ur, n_vv, n_rr,
     n_uv, n_ur, y_uudr, n_uudr, max_thrust, max_rudder,
     h_kp, h_kd, h_ki, h_limit, s_kp, s_kd, s_ki, s_limit) = (c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7],
     c[8], c[9], c[10], c[11], c[12], c[13], c[14], c[15], c[16], c[17], c[18], c[19], c[20], c[21], c[22],
     c[23], c[24], c[25], c[26], c[27], c[28], c[29])  # fmt: skip
    m11 = m_ - x_udot
    m22 = m_ - y_vdot
    m23 = -y_rdot
    m32 = -n_vdot
    m33 = izz - n_rdot
    det = m22 * m33 - m23 * m32
    two_pi = 2.0 * np.pi
    for m in range(psi_c.shape[0]):
        u, v, r, x, y, psi = state[0], state[1], state[2], state[3], state[4], state[5]
        i_psi = 0.0
        i_u = 0.0
        previous_u = 0.0
        started = False
        u_d = u_c[m]
        j = 0
        for k in range(1, steps + 1):
            # control.pid_step, "positional"
            e_psi = (psi_c[m] - psi + np.pi) % two_pi - np.pi
            e_u = u_d - u
            de_psi = -r
            de_u = -(u - previous_u) / dt if started else 0.0
            i_psi = _clip(i_psi + h_ki * e_psi * dt, -h_limit, h_limit)
            i_u = _clip(i_u + s_ki * e_u * dt, -s_limit, s_limit)
            feed_forward = -x_uu * u_d * abs(u_d)
            thrust = _clip(feed_forward + s_kp * e_u + s_kd * de_u + i_u, -max_thrust, max_thrust)
            rudder = _clip(-(h_kp * e_psi + h_kd * de_psi + i_psi), -max_rudder, max_rudder)
            previous_u = u
            started = True
            # dynamics.body_forces
            uu = u * u
            flow_x = x_uu * u * abs(u)
            flow_y = y_vv * v * abs(v) + y_uv * u * v
            flow_n = n_vv * v * abs(v) + n_uv * u * v
            rate_x = (x_vr + m_) * v * r + x_rr * r * r
            rate_y = y_rr * r * abs(r) + (y_ur - m_) * u * r
            rate_n = n_rr * r * abs(r) + n_ur * u * r
            ctrl_y = y_uudr * uu * rudder
            ctrl_n = n_uudr * uu * rudder
            if mode == 1:
                f1 = flow_x + rate_x + thrust + weight * forces[0]
                f2 = flow_y + rate_y + ctrl_y + weight * forces[1]
                f3 = flow_n + rate_n + ctrl_n + weight * forces[2]
            elif mode == 2:
                f1 = (1.0 - weight) * flow_x + weight * forces[0] + rate_x + thrust
                f2 = (1.0 - weight) * flow_y + weight * forces[1] + rate_y + ctrl_y
                f3 = (1.0 - weight) * flow_n + weight * forces[2] + rate_n + ctrl_n
            elif mode == 3:
                f1 = (1.0 - weight) * (flow_x + rate_x) + weight * forces[0] + thrust
                f2 = (1.0 - weight) * (flow_y + rate_y) + weight * forces[1] + ctrl_y
                f3 = (1.0 - weight) * (flow_n + rate_n) + weight * forces[2] + ctrl_n
            else:
                f1 = flow_x + rate_x + thrust
                f2 = flow_y + rate_y + ctrl_y
                f3 = flow_n + rate_n + ctrl_n
            # dynamics.accelerations and the kinematics, then (5.12)
            udot = f1 / m11
            vdot = (m33 * f2 - m23 * f3) / det
            rdot = (m22 * f3 - m32 * f2) / det
            cos_psi = math.cos(psi)
            sin_psi = math.sin(psi)
            xdot = u * cos_psi - v * sin_psi - u_sub
            ydot = u * sin_psi + v * cos_psi
            psidot = r
            u = u + udot * dt
            v = v + vdot * dt
            r = r + rdot * dt
            x = x + xdot * dt
            y = y + ydot * dt
            psi = psi + psidot * dt
            if k % check != 0 and k != steps:
                continue
            poses[m, j, 0] = x
            poses[m, j, 1] = y
            poses[m, j, 2] = psi
            finite = (math.isfinite(u) and math.isfinite(v) and math.isfinite(r) and math.isfinite(x)
                      and math.isfinite(y) and math.isfinite(psi))  # fmt: skip
            poses[m, j, 3] = 1.0 if finite else 0.0
            j += 1
