"""PID gain design for the library vehicles (docs/pid-tuning.md): the rules that give the gains
in physics/vehicles.py, on (5.10) linearised about straight flight, so they can be re-derived."""

from __future__ import annotations

import math

import numpy as np

from nearsub.common.physics.vehicles import Gains, PidTuning, Vehicle


def linearised_sway_yaw(vehicle: Vehicle, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """(5.10) linearised about straight flight at u = speed: [v', r'] = A [v, r] + b delta_r.
    The quadratic drag terms vanish at v = r = 0; surge decouples."""
    m = vehicle.mass
    mass = np.array([[m - vehicle.Y_vdot, -vehicle.Y_rdot], [-vehicle.N_vdot, vehicle.Izz - vehicle.N_rdot]])
    forces = np.array(
        [
            [vehicle.Y_uv * speed, (vehicle.Y_ur - m) * speed],
            [vehicle.N_uv * speed, vehicle.N_ur * speed],
        ]
    )
    control = np.array([vehicle.Y_uudr, vehicle.N_uudr]) * speed**2
    return np.linalg.solve(mass, forces), np.linalg.solve(mass, control)


def closed_loop_poles(vehicle: Vehicle, speed: float, heading: Gains) -> np.ndarray:
    """Poles of the linear sway-yaw model under the positional heading PID of control.py.

    With psi_d = 0 the rudder is -(Kp e - Kd r + Ki int e) = Kp psi + Kd r + Ki int psi.
    States: v, r, psi, int psi.
    """
    a, b = linearised_sway_yaw(vehicle, speed)
    closed = np.zeros((4, 4))
    closed[:2, :2] = a
    closed[2, 1] = 1.0
    closed[3, 2] = 1.0
    closed[:2, 1] += b * heading.kd
    closed[:2, 2] += b * heading.kp
    closed[:2, 3] += b * heading.ki
    return np.linalg.eigvals(closed)


def design_heading_gains(vehicle: Vehicle, speed: float, band_deg: float = 10.0, zeta: float = 0.9) -> Gains:
    """The tuning rule of docs/pid-tuning.md, on the linearised model at the design speed:
    Kp saturates the rudder at `band_deg` of heading error; Kd is the smallest gain whose PD loop
    has every pole damped by at least `zeta`; Ki = Kp w / 10 with w the slowest PD pole (the rule
    of the depth loop in Fossen's MSS SIMremus100.m). Integral clipped at 0.1 rad of rudder."""
    kp = vehicle.max_rudder / math.radians(band_deg)
    for kd in np.arange(0.0, 50.0, 0.01):
        poles = closed_loop_poles(vehicle, speed, Gains(kp=kp, kd=kd))
        pd_poles = poles[np.abs(poles) > 1e-9]  # drop the integrator's pole at 0 (Ki = 0)
        if np.all(-pd_poles.real >= zeta * np.abs(pd_poles)):
            slowest = float(np.min(np.abs(pd_poles)))
            return Gains(kp=kp, kd=float(kd), ki=kp * slowest / 10.0, integral_limit=0.1)
    raise ValueError(f"no Kd below 50 damps the heading loop of {vehicle.name} to {zeta}")


def design_speed_gains(vehicle: Vehicle, speed: float, ratio: float = 3.0) -> Gains:
    """Speed loop on top of the feed-forward -X_u|u| u_d|u_d| of control.py: the linearised surge
    pole (2 |X_u|u|| u / M11) is made `ratio` times faster; Ki = Kp w / 10 as for heading;
    integral clipped at half the thrust limit."""
    drag = 2.0 * abs(vehicle.X_uu) * speed
    kp = (ratio - 1.0) * drag
    return Gains(kp=kp, ki=kp * ratio * drag / vehicle.M11 / 10.0, integral_limit=0.5 * vehicle.max_thrust)


def incremental_tuning(vehicle: Vehicle, kp_equiv: float, ki_equiv: float, dt: float) -> PidTuning:
    """Gains for the incremental form (5.21) at step dt.

    (5.21) adds tau to the old command every step, so the rudder is the running sum of
    Kp_inc e - Kd_inc r: Kd_inc = Kp dt acts as a proportional gain on heading, Kp_inc = Ki dt as
    an integral gain on the error, and no term can feed back the yaw rate itself. The same
    mapping turns the speed loop's (Kp, Ki) into (Ki dt, Kp dt).
    """
    speed = vehicle.pid.speed
    return PidTuning(
        heading=Gains(kp=ki_equiv * dt, kd=kp_equiv * dt),
        speed=Gains(kp=speed.ki * dt, kd=speed.kp * dt),
    )
