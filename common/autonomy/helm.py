"""pHelmIvP for one vehicle: behaviours as objective functions, run conditions, flags and modes.

Each behaviour is a pure function of the situation (state, time, mission variables), its settings
and its own memory, returning an objective function over (heading, speed) (`ivp.Objective`) or
None (nothing to say), and its new memory. The `Helm` keeps the variables, evaluates the mode
rules and every behaviour's conditions, posts the flags, and arbitrates by priority weight
(`ivp.arbitrate`). Semantics after the MOOS-IvP helm documentation (Benjamin et al.):

- a behaviour is *idle* while its conditions fail, *running* while they hold, *active* when it
  also returns an objective, and *complete* once it says so (then it never runs again);
- `runflag` is posted when it becomes running, `idleflag` when it becomes idle (the first
  iteration counts as a change), `activeflag` / `inactiveflag` when it starts / stops producing
  an objective, `endflag` when it completes;
- the flags of one iteration are applied after every behaviour has run, in declaration order, so
  every behaviour of an iteration sees the same variables; the next iteration sees the flags;
- the mode rules are evaluated at the start of each iteration, after the pokes;
- a flag that sets MISSION to "complete" ends the mission ("completed"), and so does a poke of
  MISSION = complete (uQueryDB's end condition in MOOS-IvP); an op-region behaviour outside its
  region ends it with "error".

The settings are pydantic models (`BEHAVIOUR_TYPES`), validated in the mission file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from nearsub.common.autonomy import behaviours, ivp, logic
from nearsub.common.autonomy.behaviours import Coordinate, Leg
from nearsub.common.physics import dynamics, proximity
from nearsub.common.physics.hull import uuv_body_outline
from nearsub.common.physics.vehicles import Vehicle

FlagValue = str | float | bool
MISSION = "MISSION"  # the variable whose value "complete" ends the mission


class _Spec(BaseModel):
    """What every behaviour has: pHelmIvP's name, pwt, condition and flags."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    name: str = Field(min_length=1)
    priority: float = Field(default=100.0, ge=0.0, description="priority weight (pwt)")
    condition: list[str] = Field(default_factory=list, description="logic conditions, ANDed")
    runflag: dict[str, FlagValue] = Field(default_factory=dict)
    idleflag: dict[str, FlagValue] = Field(default_factory=dict)
    activeflag: dict[str, FlagValue] = Field(default_factory=dict)
    inactiveflag: dict[str, FlagValue] = Field(default_factory=dict)
    endflag: dict[str, FlagValue] = Field(default_factory=dict)

    @field_validator("condition")
    @classmethod
    def _parsable(cls, value: list[str]) -> list[str]:
        return logic.check_conditions(value)


class WaypointsSpec(_Spec):
    """BHV_Waypoint (thesis section 5.7), or the modified waypoints of 6.3.2 with `modified`."""

    type: Literal["waypoints"]
    legs: list[Leg] = Field(min_length=1)
    modified: bool = False
    alpha: float = Field(default=1.0, ge=0.0, le=1.0, description="alpha of (6.2)")


class ConstantHeadingSpec(_Spec):
    type: Literal["constant_heading"]
    heading_deg: float = Field(ge=-360.0, le=360.0, description="psi [deg]")
    base_width_deg: float = Field(default=180.0, gt=0.0, le=180.0)


class ConstantSpeedSpec(_Spec):
    type: Literal["constant_speed"]
    speed: float = Field(ge=0.0, le=behaviours.MAX_SPEED)


class LoiterSpec(_Spec):
    """BHV_Loiter: round the polygon's vertices in order, forever."""

    type: Literal["loiter"]
    polygon: list[tuple[Coordinate, Coordinate]] = Field(min_length=3)
    speed: float = Field(gt=0.0, le=behaviours.MAX_SPEED)
    lead: float | None = Field(default=None, gt=0)
    capture_radius: float = Field(default=3.0, gt=0)


class StationKeepSpec(_Spec):
    """Hold a point fixed in the submarine frame (docs/design.md, "The helm")."""

    type: Literal["station_keep"]
    point: tuple[Coordinate, Coordinate]
    tolerance: float = Field(default=0.5, gt=0, description="on station within this distance [m] (an event)")
    time_constant: float = Field(default=4.0, gt=0, description="position error decay [s]")
    integral_time: float = Field(default=20.0, gt=0, description="integral action on the position error [s]")
    max_relative_speed: float = Field(default=0.5, gt=0, description="largest speed over the hull frame [m/s]")


class ApproachAsternSpec(_Spec):
    """Come up from astern to `point`: along a lane `standoff` metres farther from the hull than
    the point, merging onto the point's own line over the last `merge_distance` metres."""

    type: Literal["approach_astern"]
    point: tuple[Coordinate, Coordinate]
    closing_speed: float = Field(default=0.5, gt=0, le=behaviours.MAX_SPEED, description="over U_sub [m/s]")
    slow_distance: float = Field(default=10.0, gt=0, description="closing slows within this distance [m]")
    standoff: float = Field(default=0.0, ge=0, description="lane offset from the point, away from the hull [m]")
    merge_distance: float = Field(default=20.0, gt=0, description="the lane merges over this distance [m]")
    lead: float = Field(default=5.0, gt=0)
    capture_radius: float = Field(default=0.5, gt=0)


class HullAvoidanceSpec(_Spec):
    """Keep the predicted clearance from the hull above `min_clearance` (docs/design.md, "The helm")."""

    type: Literal["hull_avoidance"]
    priority: float = Field(default=300.0, ge=0.0)
    min_clearance: float = Field(default=0.3, ge=0, description="utility 0 below this predicted clearance [m]")
    safe_clearance: float = Field(default=1.0, gt=0, description="utility 1 above this predicted clearance [m]")
    horizon: float = Field(default=5.0, gt=0, le=60.0, description="prediction horizon [s]")
    reach: float = Field(default=15.0, gt=0, description="idle beyond this clearance of the CB [m]")


class OpRegionSpec(_Spec):
    """Ends the mission once the vehicle's CB leaves the polygon."""

    type: Literal["op_region"]
    polygon: list[tuple[Coordinate, Coordinate]] = Field(min_length=3)


class TimerSpec(_Spec):
    """No objective; completes `duration` seconds after it first runs."""

    type: Literal["timer"]
    duration: float = Field(gt=0)


BehaviourSpec = Annotated[
    WaypointsSpec
    | ConstantHeadingSpec
    | ConstantSpeedSpec
    | LoiterSpec
    | StationKeepSpec
    | ApproachAsternSpec
    | HullAvoidanceSpec
    | OpRegionSpec
    | TimerSpec,
    Field(discriminator="type"),
]
BEHAVIOUR_TYPES = (
    "waypoints",
    "constant_heading",
    "constant_speed",
    "loiter",
    "station_keep",
    "approach_astern",
    "hull_avoidance",
    "op_region",
    "timer",
)


@dataclass(frozen=True)
class Situation:
    """What a behaviour sees: the state x_k, the time, the mission variables, the vehicle, the
    submarine's speed and the interaction forces at x_k (None without a submarine)."""

    state: np.ndarray
    t: float
    variables: Mapping[str, logic.Value]
    vehicle: Vehicle
    u_sub: float
    interaction: dynamics.Interaction | None = None

    @property
    def xy(self) -> np.ndarray:
        return self.state[[dynamics.X, dynamics.Y]]


@dataclass(frozen=True)
class Result:
    """A behaviour's answer: its objective (None: nothing to say), new memory (JSON-able),
    whether it is complete (with a sentence), an end request (outcome, reason), events
    (kind, detail, data) and what the helm reports (the track-line it follows)."""

    objective: ivp.Objective | None
    memory: dict
    complete: str | None = None
    end: tuple[str, str] | None = None
    events: tuple[tuple[str, str, dict], ...] = ()
    track: tuple[tuple[float, float], tuple[float, float]] | None = None
    waypoints: behaviours.WaypointProgress | None = None


# -- the behaviours -------------------------------------------------------------------------------
def waypoints(spec: WaypointsSpec, s: Situation, memory: dict) -> Result:
    """thesis 5.7 / 6.3.2 through `behaviours.waypoints`; the track starts where it first runs."""
    x, y, psi = s.state[dynamics.X], s.state[dynamics.Y], s.state[dynamics.PSI]
    if "waypoints" in memory:
        progress = behaviours.WaypointProgress.from_dict(memory["waypoints"])
    else:
        progress = behaviours.initial_progress(spec.legs, (float(x), float(y)))
    cross_flow = behaviours.CrossFlow(s.u_sub, spec.alpha, s.vehicle.length) if spec.modified else None
    decision = behaviours.waypoints(spec.legs, progress, float(x), float(y), float(psi), cross_flow)
    events = tuple(
        (
            "waypoint",
            f"reached {spec.legs[leg].name} point {index + 1} at ({point[0]:g}, {point[1]:g})",
            {"leg": leg, "index": index, "x": float(x), "y": float(y)},
        )
        for leg, index, point in decision.captured
    )
    progress = decision.progress
    memory = {"waypoints": progress.to_dict()}
    track = None
    if progress.previous is not None and decision.target is not None:
        track = (progress.previous, decision.target)
    if progress.complete:
        return Result(None, memory, f"all {progress.reached} waypoints reached", events=events, waypoints=progress)
    return Result(ivp.peak_objective(decision.psi_d, decision.u_d), memory, None, None, events, track, progress)


def constant_heading(spec: ConstantHeadingSpec, s: Situation, memory: dict) -> Result:
    psi = math.radians(spec.heading_deg)
    zaic = ivp.Zaic(psi, 0.0, math.radians(spec.base_width_deg), circular=True)
    return Result(ivp.Objective((psi, float(s.state[dynamics.U])), heading=zaic), memory)


def constant_speed(spec: ConstantSpeedSpec, s: Situation, memory: dict) -> Result:
    zaic = ivp.Zaic(spec.speed, 0.0, max(spec.speed, 0.5))
    return Result(ivp.Objective((float(s.state[dynamics.PSI]), spec.speed), speed=zaic), memory)


def loiter(spec: LoiterSpec, s: Situation, memory: dict) -> Result:
    """The waypoints behaviour over the polygon, started again at its first vertex each lap."""
    leg = Leg(name=spec.name, points=spec.polygon, speed=spec.speed, lead=spec.lead, capture_radius=spec.capture_radius)
    laps = int(memory.get("laps", 0))
    lap = WaypointsSpec(type="waypoints", name=spec.name, legs=[leg])
    inner = waypoints(lap, s, memory)
    if inner.complete is not None:
        last = tuple(spec.polygon[-1])
        restart = behaviours.WaypointProgress(previous=(float(last[0]), float(last[1])))
        ended = inner
        inner = waypoints(lap, s, {"waypoints": restart.to_dict()})
        inner = replace(inner, events=ended.events + inner.events)
        laps += 1
    return replace(inner, memory={**inner.memory, "laps": laps})


def station_keep(spec: StationKeepSpec, s: Situation, memory: dict) -> Result:
    """Position control in the submarine frame: the velocity over the hull frame
    g = clip((e + integral(e) / T_i) / tau) with e = point - position, turned into the velocity
    through the water g + (U_sub, 0) (docs/design.md, "Frames, units and signs": the water streams
    past at -U_sub), whose direction and magnitude are the peak. The integral (clipped so that it
    alone never asks more than the speed limit) removes the steady offset the interaction forces
    would leave."""
    error = np.asarray(spec.point, dtype=float) - s.xy
    dt = s.t - memory["t"] if "t" in memory else 0.0
    limit = spec.max_relative_speed * spec.time_constant * spec.integral_time
    integral = np.clip(np.asarray(memory.get("integral", (0.0, 0.0))) + error * dt, -limit, limit)
    g = (error + integral / spec.integral_time) / spec.time_constant
    norm = float(np.hypot(*g))
    if norm > spec.max_relative_speed:
        g = g * (spec.max_relative_speed / norm)
    water = g + np.array([s.u_sub, 0.0])
    psi, u = float(np.arctan2(water[1], water[0])), float(np.hypot(*water))
    distance = float(np.hypot(*error))
    on = distance <= spec.tolerance
    events = ()
    if on != memory.get("on", False):
        word = "on" if on else "off"
        detail = f"{spec.name}: {word} station, {distance:.3f} m from ({spec.point[0]:g}, {spec.point[1]:g})"
        events = (("info", detail, {"behaviour": spec.name, "on_station": on, "distance": distance}),)
    new = {"t": s.t, "integral": integral.tolist(), "on": on}
    return Result(ivp.peak_objective(psi, u), new, events=events)


def approach_astern(spec: ApproachAsternSpec, s: Situation, memory: dict) -> Result:
    """Steer at a lead point `lead` metres ahead on the lane (which runs on along the point's own
    line once past the merge), at U_sub plus the closing speed, slowed linearly within
    `slow_distance` of the point's x (slower than U_sub once past it); complete within
    `capture_radius` of the point. The lane keeps clear of the stern, where the interaction turns
    a small UUV in (docs/scenarios/recovery.md)."""
    px, py = (float(c) for c in spec.point)
    x, y = float(s.xy[0]), float(s.xy[1])
    if math.hypot(px - x, py - y) < spec.capture_radius:
        return Result(None, memory, f"at the station point ({px:g}, {py:g})")
    away = math.copysign(1.0, py)  # the lane lies on the far side of the point from the axis

    def lane(at: float) -> float:
        return py + away * spec.standoff * min(max((px - at) / spec.merge_distance, 0.0), 1.0)

    aim_x = x + spec.lead
    psi = math.atan2(lane(aim_x) - y, spec.lead)
    gap = px - x
    u = s.u_sub + spec.closing_speed * min(max(gap / spec.slow_distance, -1.0), 1.0)
    track = ((px - spec.merge_distance, lane(px - spec.merge_distance)), (px, py))
    return Result(ivp.peak_objective(psi, max(u, 0.0)), memory, track=track)


# Hull avoidance candidates: headings relative to the current one, dense near it (where the other
# behaviours steer) and coarse behind, at half and all of the top speed: nearsub's choice, 32
# predictions of the vehicle's own dynamics per helm step; the objective between them is read
# linearly (`ivp.Table`). The prediction steps 0.1 s, the step of the envelopes, which Euler
# integrates stably for every library vehicle, and checks the clearance every AVOID_CHECK steps
# (0.2 s: 0.4 m at 2 m/s).
AVOID_OFFSETS = np.radians(
    [0.0, 5.0, 10.0, 20.0, 35.0, 60.0, 90.0, 135.0, 180.0, -135.0, -90.0, -60.0, -35.0, -20.0, -10.0, -5.0]
)
AVOID_SPEED_FRACTIONS = np.array([0.5, 1.0])
AVOID_DT = 0.1
AVOID_CHECK = 2
AVOID_OUTLINE_POINTS = 12  # outline points per side for the predicted clearance


@lru_cache(maxsize=16)
def _outline(length: float, diameter: float) -> tuple[np.ndarray, np.ndarray]:
    return uuv_body_outline(length, diameter, AVOID_OUTLINE_POINTS)


def _prediction_kernel():
    """The compiled prediction (`prediction_kernel`), imported on first use: helms without hull
    avoidance do not pay numba's import."""
    from nearsub.common.autonomy import prediction_kernel

    return prediction_kernel


def predicted_clearance(s: Situation, psi_c: np.ndarray, u_c: np.ndarray, horizon: float) -> np.ndarray:
    """Least clearance [m] of the UUV's outline from the hull over `horizon`, for each commanded
    (psi_c, u_c): (5.10) with the vehicle's own coefficients and PID (pMarinePID, from rest), the
    interaction forces held at their value now, Euler steps of AVOID_DT, checked every AVOID_CHECK
    steps and at the last (`prediction_kernel.flown_poses`). A prediction that diverges counts as
    a collision."""
    kernel = _prediction_kernel()
    v = s.vehicle
    steps = int(math.ceil(horizon / AVOID_DT - 1e-9))
    checks = steps // AVOID_CHECK + (steps % AVOID_CHECK != 0)
    forces, weight, mode = np.zeros(3), 0.0, kernel.MODE_CODES[None]
    if s.interaction is not None:
        f = s.interaction
        # One vehicle's forces and weight, as (3,) and () or as the sim's one-row (1, 3) and (1,).
        forces, weight = np.ravel(f.forces).astype(float), float(np.ravel(f.weight)[0])
        mode = kernel.MODE_CODES[f.mode]
    poses = np.empty((len(psi_c), checks, 4))
    kernel.flown_poses(
        np.asarray(s.state, dtype=float), np.asarray(psi_c, dtype=float), np.asarray(u_c, dtype=float),
        kernel.vehicle_row(v), forces, weight, mode, float(s.u_sub), AVOID_DT, steps, AVOID_CHECK, poses,
    )  # fmt: skip
    bx, by = _outline(v.length, v.diameter)
    x, y, psi, finite = poses[..., 0, None], poses[..., 1, None], poses[..., 2, None], poses[..., 3] > 0.0
    with np.errstate(all="ignore"):
        c, sn = np.cos(psi), np.sin(psi)
        px = x + bx * c - by * sn
        py = y + bx * sn + by * c
        gap = proximity.hull_signed_distance(np.nan_to_num(px, nan=0.0), np.nan_to_num(py, nan=0.0)).min(axis=-1)
    return np.where(finite, gap, -np.inf).min(axis=-1, initial=np.inf)


def hull_avoidance(spec: HullAvoidanceSpec, s: Situation, memory: dict) -> Result:
    """Utility 0 where the predicted clearance falls below min_clearance, 1 above safe_clearance,
    linear between (after MOOS-IvP's collision avoidance over the closest point of approach)."""
    v = s.vehicle
    centre = float(proximity.hull_signed_distance(s.xy[0], s.xy[1]))
    if centre - v.length / 2.0 > spec.reach:
        return Result(None, memory)
    speeds = AVOID_SPEED_FRACTIONS * top_speed(v)
    headings = dynamics.wrap_angle(s.state[dynamics.PSI] + AVOID_OFFSETS)
    psi_c, u_c = np.meshgrid(headings, speeds, indexing="ij")
    least = predicted_clearance(s, psi_c.ravel(), u_c.ravel(), spec.horizon).reshape(psi_c.shape)
    span = max(spec.safe_clearance - spec.min_clearance, 1e-9)
    values = np.clip((least - spec.min_clearance) / span, 0.0, 1.0)
    table = ivp.Table(headings, speeds, values)
    return Result(ivp.Objective(None, table=table), {"least": float(least.min())})


def op_region(spec: OpRegionSpec, s: Situation, memory: dict) -> Result:
    if inside_polygon(float(s.xy[0]), float(s.xy[1]), spec.polygon):
        return Result(None, memory)
    reason = f"{spec.name}: left the operating region at ({s.xy[0]:.2f}, {s.xy[1]:.2f})"
    return Result(None, memory, end=("error", reason))


def timer(spec: TimerSpec, s: Situation, memory: dict) -> Result:
    start = memory.get("start", s.t)
    done = s.t - start >= spec.duration - 1e-9
    return Result(None, {"start": start}, f"{spec.duration:g} s elapsed" if done else None)


BEHAVIOURS = {
    "waypoints": waypoints,
    "constant_heading": constant_heading,
    "constant_speed": constant_speed,
    "loiter": loiter,
    "station_keep": station_keep,
    "approach_astern": approach_astern,
    "hull_avoidance": hull_avoidance,
    "op_region": op_region,
    "timer": timer,
}


def inside_polygon(x: float, y: float, polygon) -> bool:
    """Even-odd rule."""
    inside = False
    n = len(polygon)
    for i in range(n):
        (x0, y0), (x1, y1) = polygon[i], polygon[(i + 1) % n]
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            inside = not inside
    return inside


def top_speed(vehicle: Vehicle) -> float:
    """Where the thrust limit balances the quadratic drag of (5.11): sqrt(X_max / -X_u|u|)."""
    return math.sqrt(vehicle.max_thrust / -vehicle.X_uu)


# -- the helm ---------------------------------------------------------------------------------------
@dataclass
class Decision:
    """One helm iteration: the decision (None: no behaviour active), the winning behaviour,
    the behaviours active, the postings applied (name, value, why), the events, an end request,
    and the report of the first waypoint-like behaviour that ran."""

    choice: ivp.Choice | None
    winner: str
    active: list[str]
    postings: list[tuple[str, logic.Value, str]] = field(default_factory=list)
    events: list[tuple[str, str, dict]] = field(default_factory=list)
    end: tuple[str, str] | None = None
    track: tuple | None = None
    waypoints: behaviours.WaypointProgress | None = None

    def desired(self, state: np.ndarray) -> tuple[float, float]:
        """(u_d, psi_d): the choice, or speed 0 at the current heading (pHelmIvP's all-stop)."""
        if self.choice is None:
            return 0.0, float(state[dynamics.PSI])
        return self.choice.u, self.choice.psi


class Helm:
    """The variables, modes and behaviours of one vehicle's helm."""

    def __init__(
        self,
        specs: list,
        variables: Mapping[str, Any],
        modes: tuple[logic.ModeRule, ...],
        vehicle: Vehicle,
        u_sub: float,
        max_speed: float | None = None,
    ):
        self.specs = list(specs)
        self.conditions = [tuple(logic.parse_condition(c) for c in spec.condition) for spec in self.specs]
        self.variables: dict[str, logic.Value] = {k: logic.as_value(v) for k, v in variables.items()}
        self.modes = modes
        self.vehicle = vehicle
        self.u_sub = u_sub
        self.max_speed = top_speed(vehicle) if max_speed is None else max_speed
        self.memory: list[dict] = [{} for _ in self.specs]
        self.state: list[str] = ["none"] * len(self.specs)  # none, idle, running, active, complete

    def poke(self, values: Mapping[str, Any]) -> None:
        for name, value in values.items():
            self.variables[name] = logic.as_value(value)

    def iterate(self, state: np.ndarray, t: float, interaction: dynamics.Interaction | None = None) -> Decision:
        self.variables.update(logic.evaluate_modes(self.modes, self.variables))
        situation = Situation(state, t, dict(self.variables), self.vehicle, self.u_sub, interaction)
        postings: list[tuple[str, logic.Value, str]] = []
        objectives: list[tuple[int, float, ivp.Objective]] = []
        decision = Decision(None, "", [])
        if self.variables.get(MISSION) == "complete":  # a flag setting it ended the mission already: a poke
            decision.end = ("completed", f"{MISSION} = complete (poked)")

        def post(flags: Mapping[str, Any], spec, kind: str, why: str = "") -> None:
            for name, value in flags.items():
                value = logic.as_value(value)
                postings.append((name, value, f"{kind} of {spec.name}"))
                if name == MISSION and value == "complete" and decision.end is None:
                    decision.end = ("completed", why or f"{MISSION} = complete ({kind} of {spec.name})")

        for i, spec in enumerate(self.specs):
            before = self.state[i]
            if before == "complete":
                continue
            if not logic.all_hold(self.conditions[i], situation.variables):
                if before == "active":
                    post(spec.inactiveflag, spec, "inactiveflag")
                if before != "idle":
                    post(spec.idleflag, spec, "idleflag")
                self.state[i] = "idle"
                continue
            if before in ("none", "idle"):
                post(spec.runflag, spec, "runflag")
            result = BEHAVIOURS[spec.type](spec, situation, self.memory[i])
            self.memory[i] = result.memory
            decision.events.extend(result.events)
            if decision.waypoints is None and result.waypoints is not None:
                decision.waypoints, decision.track = result.waypoints, result.track
            if result.end is not None and decision.end is None:
                decision.end = result.end
            now = "active" if result.objective is not None else "running"
            if now == "active" and before != "active":
                post(spec.activeflag, spec, "activeflag")
            if now != "active" and before == "active":
                post(spec.inactiveflag, spec, "inactiveflag")
            if result.objective is not None:
                objectives.append((i, spec.priority, result.objective))
            if result.complete is not None:
                post(spec.endflag, spec, "endflag", result.complete)
                decision.events.append(("info", f"{spec.name} complete: {result.complete}", {"behaviour": spec.name}))
                now = "complete"
            self.state[i] = now
        # Ties between peaks go to the higher priority, then the earlier declaration.
        objectives.sort(key=lambda item: (-item[1], item[0]))
        current = (float(state[dynamics.PSI]), float(state[dynamics.U]))
        decision.choice = ivp.arbitrate([(w, o) for _, w, o in objectives], self.max_speed, current)
        decision.active = [self.specs[i].name for i, _, _ in objectives]
        if decision.choice is not None and decision.choice.winner >= 0:
            decision.winner = decision.active[decision.choice.winner]
        for name, value, _ in postings:
            self.variables[name] = value
        decision.postings = postings
        return decision

    def progress(self) -> dict:
        return {"variables": dict(self.variables), "memory": self.memory, "state": self.state}

    def restore(self, progress: dict) -> None:
        self.variables = {k: logic.as_value(v) for k, v in progress["variables"].items()}
        self.memory = [dict(m) for m in progress["memory"]]
        self.state = list(progress["state"])
