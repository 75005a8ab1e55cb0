"""The vectorised batch engine: N independent UUVs run in one process as numpy arrays.

It calls the functions the apps' cores call, on arrays: `behaviours.steer`,
`behaviours.nuv_heading_offset` and `behaviours.guard_heading_offset` (helm), `control.pid_step`
(pid), `interaction.interaction_at`, `dynamics.step` and `events.classify` (sim), in the thesis
order and with the same multi-rate schedule (the helm runs every `period` steps and the pid holds
its last desired state). The surrogate (and the LF, when it is in the loop) is asked once per step
for the whole batch, in-process. Nothing is re-implemented, so a
cell run here and the same cell run as a mission through the launcher agree (tests check it).

Each UUV follows one track-line from its start; it stops being integrated at a collision (its
state is frozen there), as the sim ends a mission at a collision.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np

from nearsub.common.autonomy import behaviours, control
from nearsub.common.mission.cores import guard_clearance, make_helm
from nearsub.common.mission.schema import Mission
from nearsub.common.physics import dynamics
from nearsub.common.physics import proximity as events
from nearsub.common.surrogate.interaction import ForceModel, interaction_at

OUTCOMES = ("safe", "large_stray", "close_call", "collision", "infeasible")  # codes 0..4


@dataclass
class BatchResult:
    """Per UUV: outcome code (index into OUTCOMES), closest approach of its CB to the hull [m]
    (negative inside), largest distance from the track-line [m], final state (N, 6), steps
    integrated."""

    outcome: np.ndarray
    closest: np.ndarray
    max_cross_track: np.ndarray
    final: np.ndarray
    steps: np.ndarray

    def outcome_names(self) -> list[str]:
        return [OUTCOMES[code] for code in self.outcome]


def _keep(memory: control.PidState, keep: np.ndarray) -> control.PidState:
    """The controller memory of the UUVs still flying."""
    return control.PidState(*(np.asarray(getattr(memory, f.name))[keep] for f in fields(memory)))


def run_batch(
    mission: Mission,
    starts: np.ndarray,
    track_ends: np.ndarray,
    surrogate: ForceModel | None = None,
    active: np.ndarray | None = None,
    on_step: Callable[[int, int], None] | None = None,
    delta: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    time_offset: np.ndarray | None = None,
) -> BatchResult:
    """Fly N UUVs of `mission` (its vehicle, environment, helm, pid and sim settings and the speed
    and lead of its first leg) from `starts` (N, 6 state) along the track-lines from their start
    positions to `track_ends` (N, 2), for mission.max_steps steps. `active` masks cells to run;
    `on_step(done, total)` follows the progress (a progress bar).

    The largest cross-track error is measured from the track-line through the start and the end,
    extended both ways: a UUV that drops back behind its start is on its line, not straying
    (`behaviours.track_geometry`, the helm's own geometry).

    Only the UUVs still flying are computed: the arrays shrink when some collide. Every function
    works row by row (the surrogate's `predict_rows` too), so a UUV's numbers do not depend on
    which others fly with it.

    `delta(x_c, uuvs)` replaces the surrogate's mean residual for the sim at those UUVs (indices
    into `starts`): a posterior sample per UUV (`interaction_at`). The helm's N_uv compensation
    keeps the mean: a vehicle carries the surrogate, not the field it flies in. `time_offset`
    (N,) [s] shifts each UUV's clock in the waves, which is a shift of the wave phase it meets."""
    vehicle = mission.vehicle_model
    helm, pid, sim = mission.apps.helm, mission.apps.pid, mission.apps.sim
    leg = helm.legs[0] if helm.legs else None
    env = mission.environment.dynamics()
    dt = mission.dt
    n = len(starts)
    active = np.ones(n, dtype=bool) if active is None else np.asarray(active, dtype=bool).copy()
    final = np.array(starts, dtype=float)
    cross_flow = None
    if helm.modified:
        cross_flow = behaviours.CrossFlow(mission.environment.u_sub, helm.alpha, vehicle.length)
    gamma = helm.gamma or float(behaviours.gamma_from_m11(vehicle.thesis_M11 or vehicle.M11))
    clearance = guard_clearance(mission)
    guard_step = math.radians(helm.guard_rate_deg) * dt * helm.period
    use_surrogate = surrogate is not None and mission.environment.submarine
    compensate = helm.compensated and use_surrogate
    interact = use_surrogate and sim.interaction != "off"

    collided = np.zeros(n, dtype=bool)
    close_call = np.zeros(n, dtype=bool)
    closest = np.full(n, np.inf)
    max_cross = np.zeros(n)
    steps = np.zeros(n, dtype=int)
    limits_low = np.array([-vehicle.max_thrust, -vehicle.max_rudder])
    limits_high = np.array([vehicle.max_thrust, vehicle.max_rudder])

    flying = np.flatnonzero(active)  # indices of the UUVs still integrated, in order
    # A behaviour list runs the helm app's own helm, one per UUV (not vectorised: docs/design.md, "The helm").
    helms = [make_helm(mission) for _ in flying] if helm.behaviours else None
    x = final[flying]
    track_start = x[:, [dynamics.X, dynamics.Y]].copy()
    track_end = np.asarray(track_ends, dtype=float)[flying]
    memory = control.PidState.zeros((len(flying),))
    u_d = np.zeros(len(flying))
    psi_d = np.zeros(len(flying))
    delta_psi = np.zeros(len(flying))  # the guarded N_uv offsets of the last helm step
    command = np.zeros((len(flying), 2))
    offsets = None if time_offset is None else np.asarray(time_offset, dtype=float)

    def ask(x: np.ndarray, sampled: bool):  # one query for the whole batch; sweeps need no std
        own = (lambda X, rows: delta(X, flying[rows])) if sampled else None  # rows of the UUVs flying now
        rho, mode = mission.environment.rho, sim.interaction
        return interaction_at(surrogate, x, vehicle, rho, mode, with_std=False, weighted_only=True, delta=own)

    for step in range(mission.max_steps):
        if flying.size == 0:
            break
        t = step * dt if offsets is None else step * dt + offsets[flying]
        helm_runs = step % helm.period == 0
        seen = believed = None
        if interact or (compensate and helm_runs):
            seen = believed = ask(x, delta is not None)
        if compensate and helm_runs and delta is not None:
            believed = ask(x, False)
        if helm_runs:  # helm(x_k)
            if helms is not None:  # a behaviour list: each UUV's own helm
                speed, heading = _arbitrated(helms, x, t, seen)
            else:
                xy = x[:, [dynamics.X, dynamics.Y]]
                speed, heading = behaviours.steer(
                    track_start, track_end, xy, leg.speed, leg.lead, leg.lead_damper, cross_flow
                )
            if compensate:
                commanded = behaviours.nuv_heading_offset(
                    believed.applied[:, 2], speed, vehicle.compensation_N_uv, gamma
                )
                delta_psi = behaviours.guard_heading_offset(
                    x[:, dynamics.X],
                    x[:, dynamics.Y],
                    heading,
                    commanded,
                    delta_psi,
                    vehicle.length,
                    vehicle.diameter,
                    clearance,
                    guard_step,
                    speed,
                    mission.environment.u_sub,
                    behaviours.course_lag(vehicle, speed),
                ).delta_psi
                heading = heading + delta_psi
            u_d = np.broadcast_to(np.asarray(speed, dtype=float), heading.shape).copy()
            psi_d = heading
        if step % pid.period == 0:  # pid
            memory, out = control.pid_step(memory, u_d, psi_d, x, vehicle, vehicle.pid, dt * pid.period, pid.form)
            command = np.clip(np.stack([out.thrust, out.rudder], axis=-1), limits_low, limits_high)
        interaction = seen.interaction if interact else None  # sim: x_k -> x_{k+1}
        x = dynamics.step(x, command, vehicle, env, dt * sim.period, sim.integrator, t, interaction)
        steps[flying] += 1
        found = events.classify(
            x[:, dynamics.X], x[:, dynamics.Y], x[:, dynamics.PSI], vehicle.length, vehicle.diameter
        )
        close_call[flying] |= found.close_call
        closest[flying] = np.minimum(closest[flying], found.centre_clearance)
        cross = np.abs(behaviours.track_geometry(track_start, track_end, x[:, [dynamics.X, dynamics.Y]])[3])
        max_cross[flying] = np.maximum(max_cross[flying], cross)
        if found.collision.any():  # the sim ends a mission at a collision: freeze those UUVs there
            final[flying] = x
            collided[flying[found.collision]] = True
            keep = ~found.collision
            flying, x, track_start, track_end = flying[keep], x[keep], track_start[keep], track_end[keep]
            memory, u_d, psi_d, command = _keep(memory, keep), u_d[keep], psi_d[keep], command[keep]
            delta_psi = delta_psi[keep]
            helms = None if helms is None else [h for h, k in zip(helms, keep, strict=True) if k]
        if on_step is not None:
            on_step(step + 1, mission.max_steps)
    final[flying] = x

    outcome = np.select(
        [~active, collided, close_call, max_cross > events.STRAY_LIMIT],
        [
            OUTCOMES.index("infeasible"),
            OUTCOMES.index("collision"),
            OUTCOMES.index("close_call"),
            OUTCOMES.index("large_stray"),
        ],
        OUTCOMES.index("safe"),
    )
    return BatchResult(outcome, closest, max_cross, final, steps)


def _arbitrated(helms: list, x: np.ndarray, t: float, seen) -> tuple[np.ndarray, np.ndarray]:
    """u_d and psi_d from each UUV's helm at its state, with its interaction forces when asked."""
    desired = np.empty((len(helms), 2))
    for i, one in enumerate(helms):
        interaction = None
        if seen is not None:
            f = seen.interaction
            interaction = dynamics.Interaction(f.forces[i], f.weight[i], f.mode)
        desired[i] = one.iterate(x[i], t, interaction).desired(x[i])
    return desired[:, 0], desired[:, 1]
