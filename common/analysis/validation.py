"""Validation of the 3-DOF simulator against thesis section 5.10, and of the library PID gains.

Every case runs in-process with `dynamics.step` (explicit Euler (5.12), dt = 0.01 s) and returns
a `Row`. Open-loop cases hold the speed by freezing u at the stated value after every step: the
thesis's yaw rates are reproduced with the speed held (docs/physics.md), and a frozen u is the
limit of an infinitely stiff speed loop, with no extra gain to choose. (X_prop = 3.86 N plus a
P loop of 100 N/(m/s) gives -10.03 deg/s for REMUS instead of -10.08; both are within 2 % of the
thesis.)

The library PID gains are designed in autonomy/pid_design.py (docs/pid-tuning.md); the cases here
check them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from nearsub.common.autonomy.control import PidState, pid_step
from nearsub.common.autonomy.pid_design import closed_loop_poles, incremental_tuning
from nearsub.common.physics.dynamics import PSI, Environment, R, U, step
from nearsub.common.physics.vehicles import NPS_AUV_II, REMUS100, SDV, PidTuning, Vehicle

DT = 0.01  # validation step [s]; the steady yaw rates are the same for dt 0.1 ... 0.001
_ENV = Environment()  # earth-fixed: no submarine, no waves

# Heading-step cases: vehicle, speed [m/s], time after which |error| must stay <= 5 deg [s].
# Typical speeds: the thesis envelopes run at U_sub = 1.5 m/s (section 5.11.2); NPS AUV II is
# checked at 1.0 m/s, between its 0.61 m/s nominal speed (2 ft/s, NPSNET-IV SUBmodel.h) and 1.5 m/s.
HEADING_CASES = ((REMUS100, 1.5, 20.0), (NPS_AUV_II, 1.0, 30.0), (SDV, 1.5, 60.0))
# Cruise-speed ranges for the stability check (physics/vehicles.py: REMUS 2.5 m/s top speed from
# Fossen's remus100, NPS max_thrust sized for 2 m/s, SDV 1.9 m/s top speed from MSS SIMnpsauv.m;
# thesis section 5.9: U_sub >= 2 knots).
CRUISE_SPEEDS = {"remus100": (1.0, 2.5), "nps_auv_ii": (0.61, 2.0), "sdv": (1.0, 1.9)}
# Incremental (5.21) heading gains as positional-equivalent (Kp on heading, Ki on error), see
# `incremental_tuning` and docs/pid-tuning.md. REMUS has none: it needs yaw-rate feedback.
INCREMENTAL_EQUIVALENT = {"nps_auv_ii": (1.0, 0.2), "sdv": (1.0, 0.08)}
INCREMENTAL_DT = 0.05  # the alpha mission's base step (missions/alpha.toml)
SETTLE_BAND_DEG = 5.0
MAX_OVERSHOOT_PCT = 10.0


@dataclass(frozen=True)
class Row:
    """One validation result. tolerance is relative (0.02 = 2 %); None for bounds (see note) and
    report-only quantities, whose target may be None too."""

    name: str
    measured: float
    target: float | None
    tolerance: float | None
    unit: str
    passed: bool
    note: str


def _relative_row(name, measured, target, rel_tol, unit, note) -> Row:
    ok = abs(measured - target) <= rel_tol * abs(target)
    return Row(name, measured, target, rel_tol, unit, bool(ok), note)


def _bound_row(name, measured, bound, unit, note) -> Row:
    return Row(name, measured, bound, None, unit, bool(measured <= bound), f"pass if <= target; {note}")


# --- open-loop manoeuvres ---------------------------------------------------------------------
def held_speed_run(
    vehicle: Vehicle,
    speed: float,
    rudder: Callable[[float], float],
    duration: float,
    dt: float = DT,
):
    """States (n, 6) of a rudder manoeuvre with u frozen at `speed` (module doc)."""
    state = np.array([speed, 0.0, 0.0, 0.0, 0.0, 0.0])
    # Trim thrust -X_u|u| u^2, which holds u in steady state; u is frozen anyway.
    thrust = -vehicle.X_uu * speed * speed
    n = int(round(duration / dt))
    out = np.empty((n, 6))
    for i in range(n):
        state = step(state, np.array([thrust, rudder(i * dt)]), vehicle, _ENV, dt)
        state[U] = speed
        out[i] = state
    return out


def rudder_step_yaw_rate(vehicle: Vehicle, speed: float, rudder_deg: float, duration: float = 15.0, dt: float = DT):
    """Yaw rate [deg/s] after a rudder step (thesis section 5.10, REMUS +4 deg), one value per
    step; the last one is the steady turn."""
    rudder = math.radians(rudder_deg)
    return np.degrees(held_speed_run(vehicle, speed, lambda t: rudder, duration, dt)[:, R])


def alternating_rudder_yaw_rate(
    vehicle: Vehicle,
    speed: float,
    rudder_deg: float = 15.0,
    leg: float = 45.0,
    legs: int = 3,
    dt: float = DT,
) -> float:
    """Yaw-rate amplitude [deg/s]: mean |r| at the end of legs 2..legs of a +/- rudder square
    wave switched every `leg` seconds (thesis section 5.10, NPS AUV II +/-15 deg every 45 s)."""
    rudder = math.radians(rudder_deg)
    states = held_speed_run(vehicle, speed, lambda t: rudder if int(t // leg) % 2 == 0 else -rudder, legs * leg, dt)
    ends = [int(round(k * leg / dt)) - 1 for k in range(2, legs + 1)]
    return float(np.degrees(np.mean(np.abs(states[ends, R]))))


# --- heading loop -----------------------------------------------------------------------------
def heading_step(
    vehicle: Vehicle,
    speed: float,
    duration: float,
    step_deg: float = 90.0,
    tuning: PidTuning | None = None,
    form: str = "positional",
    dt: float = DT,
):
    """Closed-loop heading step from straight flight at `speed`: time, heading [deg], rudder [deg]
    and u arrays. The PID (control.pid_step) holds the speed too; the incremental form starts
    from the trim thrust, its "old command" at t = 0."""
    tuning = tuning or vehicle.pid
    state = np.array([speed, 0.0, 0.0, 0.0, 0.0, 0.0])
    memory = replace(PidState.zeros(), thrust=np.asarray(-vehicle.X_uu * speed * speed))
    psi_d = math.radians(step_deg)
    n = int(round(duration / dt))
    psi, rudder, u = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        memory, cmd = pid_step(memory, speed, psi_d, state, vehicle, tuning, dt, form)
        state = step(state, np.array([cmd.thrust, cmd.rudder]), vehicle, _ENV, dt)
        psi[i], rudder[i], u[i] = state[PSI], cmd.rudder, state[U]
    return dt * np.arange(1, n + 1), np.degrees(psi), np.degrees(rudder), u


def step_metrics(t, psi_deg, step_deg: float, settle_after: float) -> tuple[float, float]:
    """Overshoot [% of the step] and the largest absolute error [deg] from `settle_after` on."""
    overshoot = max(0.0, (float(np.max(psi_deg)) - step_deg) / step_deg * 100.0)
    late = np.abs(psi_deg[t >= settle_after] - step_deg)
    return overshoot, float(np.max(late))


# --- the table --------------------------------------------------------------------------------
def _open_loop_rows() -> list[Row]:
    # REMUS at its trim speed sqrt(3.86 / 1.62) = 1.544 m/s (Prestero 2001, table C.9).
    remus_r = rudder_step_yaw_rate(REMUS100, 1.544, 4.0)
    fine = 5  # dt / 5 = 0.002 s; compare the whole transient at the coarse steps
    remus_fine = rudder_step_yaw_rate(REMUS100, 1.544, 4.0, dt=DT / fine)[fine - 1 :: fine]
    remus = float(remus_r[-1])
    dt_change = float(np.max(np.abs(remus_r - remus_fine))) / abs(remus) * 100.0
    nps = alternating_rudder_yaw_rate(NPS_AUV_II, 0.61)  # 2 ft/s (NPSNET-IV SUBmodel.h nominal speed)
    sdv = alternating_rudder_yaw_rate(SDV, 1.5)  # the envelope speed (thesis section 5.11.2)
    return [
        _relative_row(
            "REMUS 100 +4 deg rudder step, steady yaw rate",
            remus,
            -10.04,
            0.02,
            "deg/s",
            "thesis 5.10 (experiment about -10); u held at 1.544 m/s",
        ),
        _bound_row(
            "REMUS 100 rudder step: largest r(t) change from dt=0.01 to 0.002, % of steady r",
            dt_change,
            0.5,
            "%",
            "Euler step-size insensitivity over the whole transient",
        ),
        _relative_row(
            "NPS AUV II +/-15 deg every 45 s, yaw-rate amplitude",
            nps,
            7.24,
            0.03,
            "deg/s",
            "thesis 5.10 (experiment about 7.5); u held at 0.61 m/s",
        ),
        Row(
            "SDV +/-15 deg every 45 s, yaw-rate amplitude",
            sdv,
            None,
            None,
            "deg/s",
            True,
            "report only (no thesis figure); u held at 1.5 m/s",
        ),
    ]


def _mass_rows() -> list[Row]:
    return [
        _relative_row(
            "NPS AUV II M11 = m - X_udot",
            NPS_AUV_II.M11,
            212.9,
            0.005,
            "kg",
            "thesis section 6.3.1",
        ),
        _relative_row("SDV M11 = m - X_udot", SDV.M11, 6020.0, 0.005, "kg", "thesis section 6.3.1"),
        Row(
            "REMUS 100 M11 = m - X_udot",
            REMUS100.M11,
            33.6,
            None,
            "kg",
            True,
            "informational: Prestero gives 30.48 + 0.93 = 31.41 kg; no documented combination "
            "gives the thesis 33.6 kg (docs/physics.md)",
        ),
    ]


def _step_rows(label: str, t, psi, settle: float, overshoot_note: str, settle_note: str) -> list[Row]:
    """Overshoot and late error of a 90 deg heading step, each against its bound."""
    overshoot, late = step_metrics(t, psi, 90.0, settle)
    return [
        _bound_row(f"{label}: overshoot", overshoot, MAX_OVERSHOOT_PCT, "%", overshoot_note),
        _bound_row(f"{label}: max abs error after {settle:g} s", late, SETTLE_BAND_DEG, "deg", settle_note),
    ]


def _heading_rows() -> list[Row]:
    rows = []
    for vehicle, speed, settle in HEADING_CASES:
        t, psi, _, _ = heading_step(vehicle, speed, 1.5 * settle)
        label = f"{vehicle.name} 90 deg heading step at {speed} m/s"
        rows += _step_rows(label, t, psi, settle, "positional PID", "settling")
        lo, hi = CRUISE_SPEEDS[vehicle.name]
        worst = max(
            float(np.max(closed_loop_poles(vehicle, u, vehicle.pid.heading).real)) for u in np.linspace(lo, hi, 8)
        )
        rows.append(
            Row(
                f"{vehicle.name} linear heading loop over {lo}-{hi} m/s: max Re(pole)",
                worst,
                0.0,
                None,
                "1/s",
                bool(worst < 0.0),
                "pass if < 0 (stable at every cruise speed)",
            )
        )
    for vehicle, speed, settle in HEADING_CASES:
        if vehicle.name not in INCREMENTAL_EQUIVALENT:
            continue
        tuning = incremental_tuning(vehicle, *INCREMENTAL_EQUIVALENT[vehicle.name], INCREMENTAL_DT)
        t, psi, _, _ = heading_step(vehicle, speed, 1.5 * settle, tuning=tuning, form="incremental", dt=INCREMENTAL_DT)
        label = f"{vehicle.name} 90 deg step, incremental (5.21), dt={INCREMENTAL_DT}"
        rows += _step_rows(label, t, psi, settle, "optional form", "optional form")
    return rows


def run_validation() -> list[Row]:
    """All validation rows: thesis 5.10 manoeuvres, M11 values, heading-loop checks."""
    return _open_loop_rows() + _mass_rows() + _heading_rows()


def format_table(rows: list[Row]) -> str:
    """Markdown table of the rows (used in docs/physics.md)."""
    lines = [
        "| case | measured | target | tolerance | unit | passed | note |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        target = "-" if r.target is None else f"{r.target:g}"
        tol = "-" if r.tolerance is None else f"{r.tolerance * 100:g} %"
        passed = "yes" if r.passed else "NO"
        lines.append(f"| {r.name} | {r.measured:.4g} | {target} | {tol} | {r.unit} | {passed} | {r.note} |")
    return "\n".join(lines)
