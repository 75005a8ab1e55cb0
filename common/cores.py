"""The lock-stepped app cores: helm, pid and sim. Each wires messages to the pure functions of
behaviours, control and dynamics, and follows the lifecycle of `lifecycle.Core`. They know
nothing of Zenoh; `apps/` runs them as processes and `lifecycle.run_inprocess` runs them here.
"""

from __future__ import annotations

import math

import numpy as np

from . import behaviours, control, dynamics
from .lifecycle import Iteration
from .messages import Desired, Event, HelmProgress, Input, Message, State
from .mission import Mission


def state_array(message: State) -> np.ndarray:
    return np.array([message.u, message.v, message.r, message.x, message.y, message.psi])


def state_message(values: np.ndarray, step: int, t: float, source: str) -> State:
    u, v, r, x, y, psi = (float(value) for value in values)
    return State(step=step, t=t, source=source, u=u, v=v, r=r, x=x, y=y, psi=psi)


class HelmCore:
    """pHelmIvP: the waypoints behaviour (thesis section 5.7) turning x_k into x_d,k."""

    role = "helm"
    inputs = ("state",)
    outputs = ("desired", "helm")

    def __init__(self, mission: Mission):
        self.settings = mission.apps.helm
        self.legs = self.settings.legs
        self.progress_state = behaviours.initial_progress(self.legs, (mission.start.x, mission.start.y))
        self.state: State | None = None

    def startup(self) -> list[tuple[str, Message]]:
        return []

    def new_mail(self, mail: dict[str, Message]) -> None:
        if "state" in mail:
            self.state = mail["state"]

    def iterate(self, step: int, t: float) -> Iteration:
        s = self.state
        decision = behaviours.waypoints(self.legs, self.progress_state, s.x, s.y, s.psi)
        self.progress_state = decision.progress
        result = Iteration()
        for leg, index, point in decision.captured:
            result.events.append(
                Event(
                    step=step,
                    t=t,
                    source=self.role,
                    kind="waypoint",
                    detail=f"reached {self.legs[leg].name} point {index + 1} at ({point[0]:g}, {point[1]:g})",
                    data={"leg": leg, "index": index, "x": s.x, "y": s.y},
                )
            )
        progress = decision.progress
        result.outputs.append(("desired", Desired(step=step, t=t, source=self.role, u_d=decision.u_d, psi_d=decision.psi_d)))
        result.outputs.append(
            (
                "helm",
                HelmProgress(
                    step=step,
                    t=t,
                    source=self.role,
                    behaviour=self.settings.behaviour,
                    leg=progress.leg,
                    waypoint_index=progress.index,
                    waypoints_reached=progress.reached,
                    psi_d=decision.psi_d,
                    complete=progress.complete,
                ),
            )
        )
        if progress.complete:
            result.end, result.reason = "completed", f"all {progress.reached} waypoints reached"
        return result

    def progress(self) -> dict:
        return {"waypoints": self.progress_state.to_dict()}

    def restore(self, progress: dict) -> None:
        self.progress_state = behaviours.WaypointProgress.from_dict(progress["waypoints"])


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
        result.outputs.append(("input", Input(step=step, t=t, source=self.role, X_prop=float(out.thrust), delta_r=float(out.rudder))))
        saturated = (bool(out.thrust_saturated), bool(out.rudder_saturated))
        for name, now, before in zip(("thrust", "rudder"), saturated, self.saturated):
            if now and not before:
                result.events.append(
                    Event(step=step, t=t, source=self.role, kind="saturation", detail=f"{name} saturated at the vehicle limit")
                )
        self.saturated = saturated
        return result

    def progress(self) -> dict:
        return {"memory": self.memory.to_dict(), "saturated": list(self.saturated)}

    def restore(self, progress: dict) -> None:
        self.memory = control.PidState.from_dict(progress["memory"])
        self.saturated = tuple(progress["saturated"])


class SimCore:
    """uSimMarine: integrates (5.10)/(5.12) from x_k and u_k to x_{k+1}."""

    role = "sim"
    inputs = ("input",)
    outputs = ("state",)

    def __init__(self, mission: Mission):
        self.vehicle = mission.vehicle_model
        self.settings = mission.apps.sim
        self.env = dynamics.Environment(u_sub=mission.environment.u_sub)
        self.base_dt = mission.dt
        self.dt = mission.dt * self.settings.period
        start = mission.start
        psi = math.radians(start.psi_deg)
        self.x = np.array([start.speed, 0.0, 0.0, start.x, start.y, psi])
        self.inp: Input | None = None

    def startup(self) -> list[tuple[str, Message]]:
        return [("state", state_message(self.x, 0, 0.0, self.role))]

    def new_mail(self, mail: dict[str, Message]) -> None:
        self.inp = mail.get("input", self.inp)

    def iterate(self, step: int, t: float) -> Iteration:
        command = np.array([self.inp.X_prop, self.inp.delta_r])
        self.x = dynamics.step(self.x, command, self.vehicle, self.env, self.dt, self.settings.integrator)
        next_step = step + self.settings.period
        next_t = next_step * self.base_dt
        result = Iteration()
        if not np.all(np.isfinite(self.x)) or abs(self.x[dynamics.U]) > self.settings.divergence_speed:
            result.end = "diverged"
            result.reason = (
                f"state diverged at t = {next_t:.2f} s (u = {self.x[dynamics.U]:.4g} m/s, "
                f"limit {self.settings.divergence_speed:g} m/s)"
            )
            result.events.append(Event(step=step, t=t, source=self.role, kind="error", detail=result.reason))
            return result
        result.outputs.append(("state", state_message(self.x, next_step, next_t, self.role)))
        return result

    def progress(self) -> dict:
        return {"x": self.x.tolist()}

    def restore(self, progress: dict) -> None:
        self.x = np.asarray(progress["x"], dtype=float)


CORES = {"helm": HelmCore, "pid": PidCore, "sim": SimCore}


def build_cores(mission: Mission) -> dict:
    return {role: factory(mission) for role, factory in CORES.items()}
