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

UUVs given the same start, track-line and clock fly the same numbers until something tells them
apart: a sampled delta (one posterior sample per UUV). They share one row of the batch until the
first step at which that row asks delta, and split into one row each there (state, controller
memory and helm copied). An envelope's K samples of a cell far from the hull, where delta is never
asked, cost one row, not K.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np

from nearsub.common.autonomy import behaviours, control
from nearsub.common.mission.cores import guard_clearance, make_helm
from nearsub.common.mission.schema import Mission
from nearsub.common.physics import dynamics
from nearsub.common.physics import proximity as events
from nearsub.common.surrogate.interaction import ForceModel, InteractionAt, interaction_at

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


def _take(memory: control.PidState, rows: np.ndarray) -> control.PidState:
    """The controller memory of rows `rows` (a mask or indices)."""
    return control.PidState(*(np.asarray(getattr(memory, f.name))[rows] for f in fields(memory)))


def _joined(first: InteractionAt, second: InteractionAt) -> InteractionAt:
    """The answers for two sets of rows, one after the other."""
    a, b = first.interaction, second.interaction
    joined = dynamics.Interaction(np.concatenate([a.forces, b.forces]), np.concatenate([a.weight, b.weight]), a.mode)
    names = [f.name for f in fields(first) if f.name != "interaction"]
    parts = {name: np.concatenate([getattr(first, name), getattr(second, name)]) for name in names}
    return InteractionAt(interaction=joined, **parts)


def _rows(at: InteractionAt, rows: np.ndarray) -> InteractionAt:
    """The answers for rows `rows` of `at`."""
    a = at.interaction
    names = [f.name for f in fields(at) if f.name != "interaction"]
    taken = {name: getattr(at, name)[rows] for name in names}
    return InteractionAt(interaction=dynamics.Interaction(a.forces[rows], a.weight[rows], a.mode), **taken)


def _same_inputs(starts: np.ndarray, track_ends: np.ndarray, offsets: np.ndarray | None) -> np.ndarray:
    """(N,) for each UUV the first UUV with the same start, track end and clock offset, to the bit."""
    columns = [np.asarray(starts, dtype=float), np.asarray(track_ends, dtype=float)]
    if offsets is not None:
        columns.append(offsets[:, None])
    bits = np.ascontiguousarray(np.hstack(columns)).view(np.uint64)
    _, first, inverse = np.unique(bits, axis=0, return_index=True, return_inverse=True)
    return first[inverse.ravel()]


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

    Only the UUVs still flying are computed: the arrays shrink when some collide, and UUVs with
    the same inputs share a row until a sampled delta parts them (module doc). Every function
    works row by row (the surrogate's `predict_rows` too), so a UUV's numbers do not depend on
    which others fly with it, nor on the order of the rows.

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

    offsets = None if time_offset is None else np.asarray(time_offset, dtype=float)
    # owner[i]: the UUV whose row carries UUV i (i itself once it flies on a row of its own).
    owner = np.arange(n)
    same = _same_inputs(
        np.asarray(starts)[active], np.asarray(track_ends)[active], None if offsets is None else offsets[active]
    )
    owner[active] = np.flatnonzero(active)[same]
    flying = np.unique(owner[active])  # the UUV of each row still integrated, in order
    shared = np.bincount(owner[active], minlength=n)[flying] > 1  # rows that carry other UUVs too
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

    def ask(x: np.ndarray, uuvs: np.ndarray, sampled: bool, asked_shared: list | None = None):
        """One query for rows x of UUVs uuvs (sweeps need no std); with `sampled` each row's own
        delta, and the shared rows that asked it appended to `asked_shared` (their answer is that
        of the row's own UUV, the first of its group)."""

        def own(X: np.ndarray, rows: np.ndarray) -> np.ndarray:
            if asked_shared is not None:
                asked_shared.append(rows[shared[rows]])
            return delta(X, uuvs[rows])

        rho, mode = mission.environment.rho, sim.interaction
        return interaction_at(
            surrogate,
            x,
            vehicle,
            rho,
            mode,
            with_std=False,
            weighted_only=True,
            delta=own if sampled else None,
            viscous=mission.surrogate.viscous,
        )

    for step in range(mission.max_steps):
        if flying.size == 0:
            break
        helm_runs = step % helm.period == 0
        seen = believed = None
        if interact or (compensate and helm_runs):
            asked_shared: list[np.ndarray] = []
            seen = believed = ask(x, flying, delta is not None, asked_shared)
            split = np.concatenate(asked_shared) if asked_shared else np.zeros(0, dtype=int)
            if split.size:  # rows whose UUVs part here: one row each for the others of their groups
                joining = np.isin(owner, flying[split]) & (owner != np.arange(n))
                others = np.flatnonzero(joining)
                row_of = np.empty(n, dtype=int)
                row_of[flying] = np.arange(len(flying))
                parent = row_of[owner[others]]
                for tally in (steps, closest, max_cross, close_call):
                    tally[others] = tally[owner[others]]
                owner[others] = others
                shared[split] = False
                extra = ask(x[parent], others, True)
                # Each row's new rows right after it: rows of one group look up the same LF table
                # cells (a cache-friendly order; the arithmetic is row by row, so any order gives the same bits).
                order = np.argsort(np.concatenate([np.arange(len(flying)), parent]), kind="stable")
                rows = np.concatenate([np.arange(len(flying)), parent])[order]
                flying, shared = np.concatenate([flying, others])[order], shared[rows]
                x, track_start, track_end, memory = x[rows], track_start[rows], track_end[rows], _take(memory, rows)
                u_d, psi_d, delta_psi, command = u_d[rows], psi_d[rows], delta_psi[rows], command[rows]
                if helms is not None:
                    helms += [copy.deepcopy(helms[r]) for r in parent]
                    helms = [helms[i] for i in order]
                seen = believed = _rows(_joined(seen, extra), order)
        if compensate and helm_runs and delta is not None:
            believed = ask(x, flying, False)
        t = step * dt if offsets is None else step * dt + offsets[flying]
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
            flying, shared, x = flying[keep], shared[keep], x[keep]
            track_start, track_end = track_start[keep], track_end[keep]
            memory, u_d, psi_d, command = _take(memory, keep), u_d[keep], psi_d[keep], command[keep]
            delta_psi = delta_psi[keep]
            helms = None if helms is None else [h for h, k in zip(helms, keep, strict=True) if k]
        if on_step is not None:
            on_step(step + 1, mission.max_steps)
    final[flying] = x
    # The UUVs still sharing a row end as the row's UUV did.
    final, collided, close_call, closest, max_cross, steps = (
        a[owner] for a in (final, collided, close_call, closest, max_cross, steps)
    )

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
