"""Speed and heading PID, thesis (5.21), in two forms (docs/design.md, "Thesis errata" 6):

- "incremental": (5.21) as printed, the new command = the old command + tau;
- "positional" (default): the form of MOOS-IvP's pMarinePID, command = P + I + D. Its gains do
  not depend on the step size, which is why it is the default.

Both saturate at the vehicle's rudder and thrust limits. Works on one vehicle (0-d arrays) or a
batch (shape (N,)), element-wise.

Conventions:
- The derivative acts on the measurement, not on the error: for heading d(e)/dt = -r between the
  helm's updates (psi_d is piecewise constant), which avoids a derivative kick at every update.
- A positive rudder gives a negative yaw rate (the Prestero / Healey sign of physics/vehicles.py),
  so the rudder is minus the heading loop output.
- The speed loop adds the feed-forward X_prop = -X_u|u| u_d|u_d| that holds u_d in steady state
  (the trim thrust against the vehicle's own axial drag).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nearsub.common.physics.dynamics import PSI, R, U, clip, components, is_batch, wrap_angle
from nearsub.common.physics.vehicles import PidTuning, Vehicle

FORMS = ("positional", "incremental")


@dataclass(frozen=True)
class PidState:
    """Integrator and memory of both loops; every field is an array (0-d or (N,))."""

    heading_integral: np.ndarray
    speed_integral: np.ndarray
    previous_u: np.ndarray
    thrust: np.ndarray
    rudder: np.ndarray
    started: np.ndarray

    @classmethod
    def zeros(cls, shape: tuple[int, ...] = ()) -> PidState:
        z = np.zeros(shape)
        return cls(z, z.copy(), z.copy(), z.copy(), z.copy(), np.zeros(shape, dtype=bool))

    def to_dict(self) -> dict[str, list | float]:
        return {k: np.asarray(v).tolist() for k, v in self.__dict__.items()}

    @classmethod
    def from_dict(cls, data: dict) -> PidState:
        return cls(**{k: np.asarray(v, dtype=bool if k == "started" else float) for k, v in data.items()})


@dataclass(frozen=True)
class PidOutput:
    thrust: np.ndarray
    rudder: np.ndarray
    thrust_saturated: np.ndarray
    rudder_saturated: np.ndarray


def pid_step(
    memory: PidState,
    u_d: np.ndarray,
    psi_d: np.ndarray,
    state: np.ndarray,
    vehicle: Vehicle,
    tuning: PidTuning,
    dt: float,
    form: str = "positional",
) -> tuple[PidState, PidOutput]:
    """One controller update from the desired [u_d, psi_d] and the measured state."""
    if form not in FORMS:
        raise ValueError(f"pid form {form!r} is not one of {FORMS}")
    u, r, psi = components(state, U, R, PSI)
    heading, speed = tuning.heading, tuning.speed
    e_psi = wrap_angle(psi_d - psi)
    e_u = u_d - u
    de_psi = -r
    if not is_batch(u):  # one vehicle: np.where costs more than the whole loop law
        de_u = -(u - memory.previous_u) / dt if memory.started else 0.0
    else:
        de_u = np.where(memory.started, -(u - memory.previous_u) / dt, 0.0)

    if form == "positional":
        i_psi = clip(memory.heading_integral + heading.ki * e_psi * dt, -heading.integral_limit, heading.integral_limit)
        i_u = clip(memory.speed_integral + speed.ki * e_u * dt, -speed.integral_limit, speed.integral_limit)
        feed_forward = -vehicle.X_uu * u_d * abs(u_d)
        thrust_cmd = feed_forward + speed.kp * e_u + speed.kd * de_u + i_u
        rudder_cmd = -(heading.kp * e_psi + heading.kd * de_psi + i_psi)
    else:
        # (5.21): tau = Kp e + Kd e' + Ki * integral(e); command_{t+1} = command_t + tau.
        i_psi = clip(memory.heading_integral + e_psi * dt, -heading.integral_limit, heading.integral_limit)
        i_u = clip(memory.speed_integral + e_u * dt, -speed.integral_limit, speed.integral_limit)
        tau_thrust = speed.kp * e_u + speed.kd * de_u + speed.ki * i_u
        tau_rudder = heading.kp * e_psi + heading.kd * de_psi + heading.ki * i_psi
        thrust_cmd = memory.thrust + tau_thrust
        rudder_cmd = memory.rudder - tau_rudder

    thrust = clip(thrust_cmd, -vehicle.max_thrust, vehicle.max_thrust)
    rudder = clip(rudder_cmd, -vehicle.max_rudder, vehicle.max_rudder)
    new_memory = PidState(
        heading_integral=i_psi,
        speed_integral=i_u,
        previous_u=np.asarray(u, dtype=float),
        thrust=thrust,
        rudder=rudder,
        started=np.ones_like(memory.started) if is_batch(u) else True,
    )
    return new_memory, PidOutput(thrust, rudder, thrust != thrust_cmd, rudder != rudder_cmd)
