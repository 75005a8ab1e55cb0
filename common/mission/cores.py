"""The lock-stepped app cores: helm, pid and sim. Each wires messages to the pure functions of
behaviours, control and dynamics, and follows the lifecycle of `lifecycle.Core`. They know
nothing of Zenoh; `apps/` runs them as processes and `lifecycle.run_inprocess` runs them here.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from nearsub.common.autonomy import behaviours, control, logic
from nearsub.common.autonomy import helm as ivphelm
from nearsub.common.mission.schema import Mission
from nearsub.common.physics import dynamics, encounters
from nearsub.common.physics import proximity as events
from nearsub.common.runtime.lifecycle import ENCOUNTERS, InProcessResult, Iteration, Schedule, run_inprocess
from nearsub.common.runtime.messages import Desired, Event, Forces, HelmProgress, Input, Message, State

if TYPE_CHECKING:
    from nearsub.common.surrogate.interaction import ForceModel, InteractionAt
    from nearsub.common.surrogate.model import Surrogate


def interaction():
    """The interaction module, imported only by a core that uses a surrogate: it loads the LF and
    scipy, which the pid and a mission without a submarine never need (their start-up)."""
    from nearsub.common.surrogate import interaction as module

    return module


def state_array(message: State) -> np.ndarray:
    return np.array([message.u, message.v, message.r, message.x, message.y, message.psi])


def state_message(values: np.ndarray, step: int, t: float, source: str) -> State:
    u, v, r, x, y, psi = (float(value) for value in values)
    return State(step=step, t=t, source=source, u=u, v=v, r=r, x=x, y=y, psi=psi)


def event(role: str, step: int, t: float, kind: str, detail: str, data: dict | None = None) -> Event:
    return Event(step=step, t=t, source=role, kind=kind, detail=detail, data=data or {})


def guard_clearance(mission: Mission) -> float:
    """The N_uv guard's tip clearance [m]: the helm setting, or one UUV diameter (schema)."""
    clearance = mission.apps.helm.guard_clearance
    return mission.vehicle_model.diameter if clearance is None else clearance


def sim_forces(mission: Mission) -> bool:
    """Whether the sim publishes the interaction forces at each state it publishes (a submarine
    and an interaction mode other than "off")."""
    return mission.environment.submarine and mission.apps.sim.interaction != "off"


def make_helm(mission: Mission) -> ivphelm.Helm:
    """The mission's helm: its behaviours, variables and mode rules (docs/design.md, "The helm")."""
    h = mission.apps.helm
    modes = tuple(rule.rule() for rule in h.modes)
    return ivphelm.Helm(
        h.behaviour_specs(), h.variables, modes, mission.vehicle_model, mission.environment.u_sub, h.max_speed
    )


class HelmCore:
    """pHelmIvP: the mission's behaviours arbitrated by priority (`autonomy.helm.Helm`; the legacy
    single behaviour is one waypoints behaviour, thesis 5.7 or 6.3.2), with N_uv compensation
    (6.3.1) modifying the chosen heading, turning x_k into x_d,k. The interaction at x_k (N_s, and
    the forces hull avoidance predicts with) is the sim's: the forces it published for x_k, a
    declared input, so each vehicle-step asks the surrogate once; only when the sim has no forces
    (interaction "off") does the helm ask itself. Pokes (`nearsub poke`) set mission variables
    from the step they arrive at."""

    role = "helm"
    outputs = ("desired", "helm")

    def __init__(self, mission: Mission, surrogate: ForceModel | None = None):
        self.settings = mission.apps.helm
        self.vehicle = mission.vehicle_model
        self.rho = mission.environment.rho
        specs = self.settings.behaviour_specs()
        self.avoids = any(spec.type == "hull_avoidance" for spec in specs)
        self.surrogate = surrogate if self.settings.compensated or self.avoids else None
        if self.settings.compensated and surrogate is None:
            raise ValueError("N_uv compensation needs the surrogate (a force model)")
        v = self.vehicle
        # gamma from (6.4) at the M11 the thesis quotes for library vehicles (5.21, 1.30, 1.03).
        self.gamma = self.settings.gamma or float(behaviours.gamma_from_m11(v.thesis_M11 or v.M11))
        # N_s is the yaw moment the interaction adds to the vehicle's own model, as the sim applies
        # it: the interaction increment in "increment" mode, the surrogate's total otherwise.
        # The sim's applied forces are the same numbers in "thesis" as in "replace" mode.
        self.interaction_mode = "increment" if mission.apps.sim.interaction == "increment" else "replace"
        self.viscous = mission.surrogate.viscous
        # The forces are an input whenever the sim has them, compensating or not, so a
        # compensating helm swapped in holds them from its predecessor's handover.
        self.inputs = ("state", "forces") if sim_forces(mission) else ("state",)
        self.shares_forces = "forces" in self.inputs
        if self.surrogate is not None and not self.shares_forces:
            interaction().prepare(self.interaction_mode)
        self.helm = make_helm(mission)
        self.report = behaviours.WaypointProgress()
        self.guard_clearance = guard_clearance(mission)
        self.guard_step = math.radians(self.settings.guard_rate_deg) * mission.dt * self.settings.period
        self.delta_psi = 0.0  # the guarded offset of the last iteration (the rate limit's reference)
        self.state: State | None = None
        self.forces: Forces | None = None
        self.straying = False

    def startup(self) -> list[tuple[str, Message]]:
        return []

    def new_mail(self, mail: dict[str, Message]) -> None:
        if "state" in mail:
            self.state = mail["state"]
        if "forces" in mail:
            self.forces = mail["forces"]
        if "poke" in mail:
            self.helm.poke(mail["poke"].values)

    def interaction_at(self, x: np.ndarray) -> tuple[dynamics.Interaction, float]:
        """The interaction at x_k as the sim applies it, and its applied N_s (section 6.3.1)."""
        if self.shares_forces:
            f = self.forces
            forces = np.array([[f.X_s, f.Y_s, f.N_s]])
            return dynamics.Interaction(forces, np.array([f.weight]), self.interaction_mode), f.applied_N
        seen = interaction().interaction_at(
            self.surrogate, x, self.vehicle, self.rho, self.interaction_mode, viscous=self.viscous
        )
        return seen.interaction, float(seen.applied[0, 2])

    def iterate(self, step: int, t: float) -> Iteration:
        s = self.state
        x = state_array(s)
        seen = self.interaction_at(x) if self.surrogate is not None and self.avoids else None
        decision = self.helm.iterate(x, t, None if seen is None else seen[0])
        choice = decision.choice
        u_d, psi_d = decision.desired(x)
        delta_psi, n_s, commanded, guard = 0.0, 0.0, 0.0, None
        if self.settings.compensated and choice is not None:
            seen = seen or self.interaction_at(x)
            n_s = seen[1]
            commanded = float(behaviours.nuv_heading_offset(n_s, u_d, self.vehicle.compensation_N_uv, self.gamma))
            guard = behaviours.guard_heading_offset(
                s.x,
                s.y,
                psi_d,
                commanded,
                self.delta_psi,
                self.vehicle.length,
                self.vehicle.diameter,
                self.guard_clearance,
                self.guard_step,
                u_d,
                self.helm.u_sub,
                behaviours.course_lag(self.vehicle, u_d),
            )
            delta_psi = float(guard.delta_psi)
            psi_d = psi_d + delta_psi
        self.delta_psi = delta_psi
        result = Iteration()
        for kind, detail, data in decision.events:
            result.events.append(event(self.role, step, t, kind, detail, data))
        for name, value, why in decision.postings:
            detail = f"{name} = {logic.format_value(value)} ({why})"
            result.events.append(event(self.role, step, t, "info", detail, {"variable": name, "value": value}))
        self.report = decision.waypoints or self.report
        cross_track = 0.0
        if decision.track is not None:
            cross_track = float(events.track_distance(s.x, s.y, *decision.track))
        straying = cross_track > events.STRAY_LIMIT
        if straying and not self.straying:
            result.events.append(
                event(
                    self.role,
                    step,
                    t,
                    "large_stray",
                    f"{cross_track:.2f} m from the track-line",
                    {"x": s.x, "y": s.y, "cross_track": cross_track},
                )
            )
        self.straying = straying
        result.outputs.append(("desired", Desired(step=step, t=t, source=self.role, u_d=u_d, psi_d=psi_d)))
        result.outputs.append(
            (
                "helm",
                HelmProgress(
                    step=step,
                    t=t,
                    source=self.role,
                    behaviour=self.settings.behaviour,
                    leg=self.report.leg,
                    waypoint_index=self.report.index,
                    waypoints_reached=self.report.reached,
                    psi_d=psi_d,
                    delta_psi=delta_psi,
                    cross_track=cross_track,
                    n_s=n_s,
                    complete=self.report.complete,
                    mode=logic.format_value(self.helm.variables.get("MODE", "")),
                    active=decision.active,
                    winner=decision.winner,
                    delta_psi_commanded=commanded,
                    guard_active=guard is not None and bool(guard.active),
                    guard_saturated=guard is not None and bool(guard.saturated),
                    guard_limit=math.inf if guard is None else float(guard.limit),
                    guard_clearance=self.guard_clearance,
                ),
            )
        )
        if decision.end is not None:
            result.end, result.reason = decision.end
        return result

    def progress(self) -> dict:
        return {
            "helm": self.helm.progress(),
            "report": self.report.to_dict(),
            "straying": self.straying,
            "delta_psi": self.delta_psi,
        }

    def restore(self, progress: dict) -> None:
        self.helm.restore(progress["helm"])
        self.report = behaviours.WaypointProgress.from_dict(progress["report"])
        self.straying = bool(progress["straying"])
        self.delta_psi = float(progress["delta_psi"])


class PidCore:
    """pMarinePID: thesis (5.21) turning x_d,k and x_k into u_k."""

    role = "pid"
    inputs = ("state", "desired")
    outputs = ("input",)

    def __init__(self, mission: Mission):
        self.vehicle = mission.vehicle_model
        self.form = mission.apps.pid.form
        self.dt = mission.dt * mission.apps.pid.period
        self.memory = control.PidState.zeros()
        self.state: State | None = None
        self.desired: Desired | None = None
        self.saturated = (False, False)

    def startup(self) -> list[tuple[str, Message]]:
        return []

    def new_mail(self, mail: dict[str, Message]) -> None:
        self.state = mail.get("state", self.state)
        self.desired = mail.get("desired", self.desired)

    def iterate(self, step: int, t: float) -> Iteration:
        self.memory, out = control.pid_step(
            self.memory,
            np.asarray(self.desired.u_d),
            np.asarray(self.desired.psi_d),
            state_array(self.state),
            self.vehicle,
            self.vehicle.pid,
            self.dt,
            self.form,
        )
        result = Iteration()
        result.outputs.append(
            ("input", Input(step=step, t=t, source=self.role, X_prop=float(out.thrust), delta_r=float(out.rudder)))
        )
        saturated = (bool(out.thrust_saturated), bool(out.rudder_saturated))
        for name, now, before in zip(("thrust", "rudder"), saturated, self.saturated, strict=True):
            if now and not before:
                result.events.append(event(self.role, step, t, "saturation", f"{name} saturated at the vehicle limit"))
        self.saturated = saturated
        return result

    def progress(self) -> dict:
        return {"memory": self.memory.to_dict(), "saturated": list(self.saturated)}

    def restore(self, progress: dict) -> None:
        self.memory = control.PidState.from_dict(progress["memory"])
        self.saturated = tuple(progress["saturated"])


class SimCore:
    """uSimMarine: integrates (5.10)/(5.12) from x_k and u_k to x_{k+1}; near the submarine with
    the surrogate's interaction forces, (5.20) (docs/design.md, "Physics decisions")."""

    role = "sim"
    inputs = ("input",)
    outputs = ("state", "forces")

    def __init__(self, mission: Mission, surrogate: ForceModel | None = None):
        self.vehicle = mission.vehicle_model
        self.rho = mission.environment.rho
        self.interaction_mode = mission.apps.sim.interaction
        self.viscous = mission.surrogate.viscous
        wanted = sim_forces(mission)
        if wanted and surrogate is None:
            raise ValueError("the sim's interaction forces need the surrogate (a force model)")
        self.surrogate = surrogate if wanted else None
        if self.surrogate is not None:
            interaction().prepare(self.interaction_mode)
        self.max_steps = mission.max_steps
        self.settings = mission.apps.sim
        self.env = mission.environment.dynamics()
        self.submarine = mission.environment.submarine
        self.close = False
        self.base_dt = mission.dt
        self.dt = mission.dt * self.settings.period
        start = mission.start
        psi = math.radians(start.psi_deg)
        self.x = np.array([start.speed, 0.0, 0.0, start.x, start.y, psi])
        self.inp: Input | None = None
        self.seen: InteractionAt | None = None  # the forces at self.x, asked when x was reached

    def startup(self) -> list[tuple[str, Message]]:
        return [*self.forces_at(0, 0.0), ("state", state_message(self.x, 0, 0.0, self.role))]

    def forces_at(self, step: int, t: float) -> list[tuple[str, Message]]:
        """Ask the surrogate about x_step, once: the forces are published just after the state
        they belong to (labelled like it, for the helm's N_s; `Iteration.then`, so the pid need not
        wait for the answer) and applied when step `step` runs."""
        if self.surrogate is None or step >= self.max_steps:
            return []
        self.seen = self.ask()
        return [("forces", forces_message(self.seen, step, t, self.role))]

    def ask(self) -> InteractionAt:
        return interaction().interaction_at(
            self.surrogate, self.x, self.vehicle, self.rho, self.interaction_mode, viscous=self.viscous
        )

    def new_mail(self, mail: dict[str, Message]) -> None:
        self.inp = mail.get("input", self.inp)

    def iterate(self, step: int, t: float) -> Iteration:
        result = Iteration()
        command = self.saturated_command(step, t, result)
        forces = None
        if self.surrogate is not None:
            if step == 0 and (outside := interaction().geometry_outside(self.vehicle)):
                result.events.append(event(self.role, step, t, "info", outside))
            if self.seen is None:  # taken over from another instance: ask again, the same answer
                self.seen = self.ask()
            forces = self.seen.interaction
        self.x = dynamics.step(self.x, command, self.vehicle, self.env, self.dt, self.settings.integrator, t, forces)
        self.seen = None
        next_step = step + self.settings.period
        next_t = next_step * self.base_dt
        if not np.all(np.isfinite(self.x)) or abs(self.x[dynamics.U]) > self.settings.divergence_speed:
            result.end = "diverged"
            result.reason = (
                f"state diverged at t = {next_t:.2f} s (u = {self.x[dynamics.U]:.4g} m/s, "
                f"limit {self.settings.divergence_speed:g} m/s)"
            )
            result.events.append(event(self.role, step, t, "error", result.reason))
            return result
        result.outputs.append(("state", state_message(self.x, next_step, next_t, self.role)))
        if self.surrogate is not None:
            result.then = lambda: Iteration(outputs=self.forces_at(next_step, next_t))
        if self.submarine:
            self.check_proximity(next_step, next_t, result)
        return result

    def saturated_command(self, step: int, t: float, result: Iteration) -> np.ndarray:
        """The input, clipped at the vehicle's limits (the pid already saturates; anything else
        reaching the sim beyond them is clipped and reported)."""
        v, raw = self.vehicle, [self.inp.X_prop, self.inp.delta_r]
        command = [
            dynamics.clip(raw[0], -v.max_thrust, v.max_thrust),
            dynamics.clip(raw[1], -v.max_rudder, v.max_rudder),
        ]
        if command != raw:  # inputs are finite (messages refuse NaN), so == compares their values
            detail = f"input {raw} clipped at the vehicle limits"
            result.events.append(event(self.role, step, t, "saturation", detail))
        return np.array(command)

    def check_proximity(self, step: int, t: float, result: Iteration) -> None:
        """Collision ends the mission (a normal ending); a close call is reported on entry."""
        u, v, r, x, y, psi = self.x
        found = events.classify(x, y, psi, self.vehicle.length, self.vehicle.diameter)
        data = {"x": float(x), "y": float(y), "psi": float(psi)}
        if bool(found.collision):
            result.events.append(
                event(self.role, step, t, "collision", f"UUV touched the submarine at ({x:.2f}, {y:.2f})", data)
            )
            result.end, result.reason = "collision", f"collision with the submarine at t = {t:.2f} s"
        close = bool(found.close_call)
        if close and not self.close:
            result.events.append(event(self.role, step, t, "close_call", f"close call at ({x:.2f}, {y:.2f})", data))
        self.close = close

    def progress(self) -> dict:
        return {"x": self.x.tolist(), "close": self.close}

    def restore(self, progress: dict) -> None:
        self.x = np.asarray(progress["x"], dtype=float)
        self.close = bool(progress["close"])


def forces_message(seen: InteractionAt, step: int, t: float, source: str) -> Forces:
    """The forces topic for one vehicle's `interaction_at` answer."""
    values = {}
    parts = (("", seen.forces), ("applied_", seen.applied), ("model_", seen.model), ("lf_", seen.lf))
    for prefix, array in (*parts, ("viscous_", seen.viscous)):
        names = ("X_s", "Y_s", "N_s") if prefix == "" else ("X", "Y", "N")
        values.update({f"{prefix}{name}": float(v) for name, v in zip(names, array[0], strict=True)})
    values.update({f"std_{name}": float(v) for name, v in zip("XYN", seen.std[0], strict=True)})
    return Forces(
        step=step,
        t=t,
        source=source,
        weight=float(seen.interaction.weight),
        delta_weight=float(seen.delta_weight[0]),
        in_domain=bool(seen.in_domain[0]),
        constraints_ok=bool(seen.constraints_ok[0]),
        outside=seen.outside(0),
        lf_held=bool(seen.lf_held[0]),
        **values,
    )


class EncounterCheck:
    """uFldCollisionDetect's role: after each step, every pair of vehicles at x_{k+1}
    (`physics.encounters`). A collision between two UUVs ends the mission, as a collision with
    the hull does; a close call is reported when a pair enters it. The clock runs it in the
    multi-process mission (`runtime.lifecycle.Observer`)."""

    def __init__(self, mission: Mission):
        members = mission.members()
        self.names = [m.vehicle_name for m in members]
        self.capsules = {
            m.vehicle_name: encounters.Capsule.of(m.vehicle_model.length, m.vehicle_model.diameter) for m in members
        }
        self.order = {name: i for i, name in enumerate(self.names)}
        self.margin = 2 * max(capsule.radius for capsule in self.capsules.values())  # the widest close call
        self.dt = mission.dt
        self.close: set[tuple[str, str]] = set()

    def observe(self, step: int, states: dict[str, State]) -> Iteration:
        """Pairs whose CBs are too far apart for a close call are skipped (`near_pairs`); those
        in a close call are always checked again, to see them leave it."""
        result = Iteration()
        label, t = step + 1, (step + 1) * self.dt
        names = [name for name in self.names if name in states]
        x = np.array([states[name].x for name in names])
        y = np.array([states[name].y for name in names])
        reaches = np.array([encounters.reach(self.capsules[name]) for name in names])
        near = {(names[i], names[j]) for i, j in encounters.near_pairs(x, y, reaches, self.margin)}
        for a, b in sorted(near | self.close, key=lambda pair: (self.order[pair[0]], self.order[pair[1]])):
            sa, sb = states[a], states[b]
            found = encounters.classify_pair(
                self.capsules[a], (sa.x, sa.y, sa.psi), self.capsules[b], (sb.x, sb.y, sb.psi)
            )
            data = {"vehicles": [a, b], "clearance": found.clearance, "a": [sa.x, sa.y], "b": [sb.x, sb.y]}
            if found.collision:
                detail = f"{a} and {b} touched at ({sa.x:.2f}, {sa.y:.2f}) and ({sb.x:.2f}, {sb.y:.2f})"
                result.events.append(event(ENCOUNTERS, label, t, "collision", detail, data))
                if result.end is None:
                    result.end, result.reason = "collision", f"collision between {a} and {b} at t = {t:.2f} s"
            if found.close_call and (a, b) not in self.close:
                detail = f"close call between {a} and {b}: {found.clearance:.2f} m apart"
                result.events.append(event(ENCOUNTERS, label, t, "close_call", detail, data))
            (self.close.add if found.close_call else self.close.discard)((a, b))
        return result


def build_fleet(mission: Mission, surrogate: ForceModel | None = None) -> dict:
    """{vehicle: {role: core}} for a mission with [[vehicles]], all sharing one surrogate."""
    return {m.vehicle_name: build_cores(m, surrogate) for m in mission.members()}


def build_cores(mission: Mission, surrogate: ForceModel | None = None) -> dict:
    return {
        "helm": HelmCore(mission, surrogate),
        "pid": PidCore(mission),
        "sim": SimCore(mission, surrogate),
    }


def mission_surrogate(mission: Mission) -> Surrogate:
    """The surrogate of the mission's `surrogate.model` file, or the shipped one when it is empty
    (`surrogate.model.load_surrogate`; raises ModelFileError for a bad file)."""
    from nearsub.common.surrogate.model import load_surrogate

    return load_surrogate(mission.surrogate.model or None)


def run_mission(mission: Mission, surrogate: ForceModel | None = None) -> InProcessResult:
    """The whole mission in this process (the reference for the multi-process run). The surrogate
    is loaded from the mission's model file when the mission needs one and none is given."""
    if surrogate is None and mission.needs_surrogate:
        surrogate = mission_surrogate(mission)
    if mission.fleet:
        cores, fleet = build_fleet(mission, surrogate), mission.lockstep()
        return run_inprocess(cores, fleet, mission.dt, mission.max_steps, observer=EncounterCheck(mission))
    return run_inprocess(build_cores(mission, surrogate), Schedule(mission.periods()), mission.dt, mission.max_steps)
