"""What the viewer page draws, computed from a mission and the messages of a run (no transport).

Two parts, both plain JSON-ready dicts:
- `static_scene(mission)`: what does not change during a run: the submarine's outline to scale,
  the waypoints and track-lines of every leg, the band where the residual GP is trained, the vehicle's
  size and the scale of the force arrows;
- `SceneModel`: fed every message of the run in arrival order (live) or log order (replay), it
  gives a `frame(t)`: the UUV's outline at its heading, its trail, the interaction force as an
  arrow and the moment as a gauge, the events up to t, and the status (simulated time, step,
  requested and achieved warp, behaviour, outcome).

Frames and signs are those of the messages (docs/design.md, "Frames, units and signs"): the
submarine frame has its origin at the submarine's centre of buoyancy, x towards the bow, y to
port, psi from +x towards +y; X_s, Y_s, N_s are body-axis forces and the yaw moment.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nearsub.common.physics.hull import submarine_outline, uuv_outline
from nearsub.common.runtime.keys import vehicle_of
from nearsub.common.runtime.messages import Event, Forces, HelmProgress, Message, MissionEnd, State

# Events drawn as markers on the map (the rest go to the list only).
MARKED_EVENTS = ("collision", "close_call", "large_stray", "waypoint", "swap")
LISTED_EVENTS = (*MARKED_EVENTS, "error", "info", "saturation")
MAX_LISTED = 200  # newest events kept in a frame's list
HULL_POINTS = 160  # stations per side of the submarine outline (smooth at any zoom on a page)
UUV_POINTS = 24
ARROW_COEFFICIENT = 0.002  # an arrow one UUV length long stands for X' or Y' = 0.002 (thesis section 5.2)
WARP_WINDOW = 2.0  # wall seconds over which the achieved warp is measured


def _round(values, digits: int = 3) -> list:
    return [round(float(v), digits) for v in values]


def _points(x, y, digits: int = 3) -> list[list[float]]:
    return [[round(float(a), digits), round(float(b), digits)] for a, b in zip(x, y, strict=True)]


def acting_band(mission) -> dict:
    """Where the surrogate's forces act: the lateral band |y| in [y_min, y_max] that satisfies the
    bounds of table 4.2 and the constraints (4.4)/(4.5) for the mission's vehicle, over the
    R_long range, on both sides of the submarine (the -y side is the mirror image, thesis section
    4.2.1). Returns {"rects": [...], "note": why there is none} ; the blend ramp inside the band's
    edges is not drawn (it is a few centimetres wide). With several vehicles, each vehicle type's
    band (its rects after the others', its note named after its vehicles)."""
    if mission is None:
        return {"rects": [], "note": "no mission: band unknown"}
    if not mission.environment.submarine:
        return {"rects": [], "note": "no submarine in this mission"}
    members = mission.members()
    if len(members) == 1:
        return _vehicle_band(members[0])
    by_type: dict[str, list] = {}
    for member in members:
        by_type.setdefault(member.vehicle_model.name, []).append(member)
    rects, notes = [], []
    for same in by_type.values():
        band = _vehicle_band(same[0])
        rects += [rect for rect in band["rects"] if rect not in rects]
        notes.append(f"{', '.join(m.vehicle_name for m in same)}: {band['note']}")
    return {"rects": rects, "note": "; ".join(notes)}


def _vehicle_band(mission) -> dict:
    """`acting_band` of a mission of one vehicle near a submarine."""
    from nearsub.common.surrogate import domain
    from nearsub.common.surrogate.interaction import geometry_outside

    if mission.apps.sim.interaction == "off":
        return {"rects": [], "note": "interaction off (apps.sim.interaction)"}
    vehicle = mission.vehicle_model
    outside = geometry_outside(vehicle)
    if outside and "zero everywhere" in outside:
        return {"rects": [], "note": outside}
    l_sub = domain.L_SUB
    lower, upper = domain.BOUNDS[1]
    y = np.linspace(lower * l_sub, upper * l_sub, 4001)
    speed = 0.5 * (domain.BOUNDS[2, 0] + domain.BOUNDS[2, 1]) * domain.KNOT  # speed and heading do not
    inputs, _ = domain.to_inputs(0.0, y, speed, 0.0, vehicle.length, vehicle.diameter)  # enter (4.4)-(4.7)
    geometry = slice(4, 6)
    inputs[:, geometry] = np.clip(inputs[:, geometry], domain.BOUNDS[geometry, 0], domain.BOUNDS[geometry, 1])
    ok = domain.constraints_ok(inputs)
    if not ok.any():
        return {"rects": [], "note": f"no lateral distance satisfies (4.4)/(4.5) for {vehicle.name}"}
    y_min, y_max = float(y[ok].min()), float(y[ok].max())
    x0, x1 = (float(b * l_sub) for b in domain.BOUNDS[0])
    rects = [
        {"x0": round(x0, 3), "x1": round(x1, 3), "y0": round(y_min, 3), "y1": round(y_max, 3)},
        {"x0": round(x0, 3), "x1": round(x1, 3), "y0": round(-y_max, 3), "y1": round(-y_min, 3)},
    ]
    return {"rects": rects, "note": f"residual GP trained for {y_min:.2f} m <= |y| <= {y_max:.2f} m"}


def force_reference(mission) -> float:
    """Force [N] drawn as an arrow one UUV length long: X' = ARROW_COEFFICIENT at the fastest leg's speed
    (coefficients scale with 0.5 rho u^2 L_uuv^2, thesis section 5.2)."""
    if mission is None:
        return 100.0
    members = mission.members()  # several vehicles: the largest of their references
    return max(
        ARROW_COEFFICIENT * 0.5 * m.environment.rho * _fastest(m) ** 2 * m.vehicle_model.length**2 for m in members
    )


def _fastest(mission) -> float:
    return max([leg.speed for leg in mission.apps.helm.legs] + [mission.start.speed, 0.5])


def frame_description(mission) -> str:
    """What the map's x and y are (docs/design.md, "Frames, units and signs"): the submarine's
    moving frame, or with no moving submarine simply the earth-fixed frame of the mission file."""
    if mission is not None and mission.environment.u_sub > 0:
        return "submarine frame (moving with it): x towards the bow, y to port"
    return "earth-fixed frame: x and y as in the mission file"


def static_scene(mission, source: str = "") -> dict:
    """The parts of the picture fixed for a run. `mission` may be None (a log without one)."""
    submarine = mission is None or mission.environment.submarine
    hull = None
    if submarine:
        hx, hy = submarine_outline(HULL_POINTS)
        hull = _points(hx, hy)
    members = [] if mission is None else mission.members()
    legs = [leg for member in members for leg in mission_legs(member)]
    if members:
        vehicle = members[0].vehicle_model
        size = {"name": vehicle.name, "length": vehicle.length, "diameter": vehicle.diameter}
    else:
        size = {"name": "uuv", "length": 2.0, "diameter": 0.3}
    return {
        "type": "scene",
        "source": source,
        "community": mission.name if mission is not None else "",
        "description": mission.description if mission is not None else "",
        "frame": frame_description(mission),
        "hull": hull,
        "legs": legs,
        "start": None if not members else [members[0].start.x, members[0].start.y],
        "starts": {m.vehicle_name: [m.start.x, m.start.y] for m in members},
        "band": acting_band(mission),
        "vehicle": size,
        "force_reference": force_reference(mission),
        "dt": None if mission is None else mission.dt,
        "warp": None if mission is None else mission.warp,
        "behaviours": list(_behaviours()),
        "behaviour": None if mission is None else mission.apps.helm.behaviour,
    }


def mission_legs(mission) -> list[dict]:
    """The waypoints and track-lines of one vehicle's mission (a member of a fleet), each leg
    from the end of the one before, the first from the vehicle's start."""
    legs = []
    previous = [mission.start.x, mission.start.y]
    for leg in mission.apps.helm.legs:
        points = [[float(px), float(py)] for px, py in leg.points]
        item = {"name": leg.name, "points": points, "track": [previous, *points], "speed": leg.speed}
        legs.append(item | {"vehicle": mission.vehicle_name} if mission.fleet else item)
        previous = points[-1]
    return legs


def _behaviours() -> tuple[str, ...]:
    from nearsub.common.mission.schema import BEHAVIOURS

    return BEHAVIOURS


@dataclass
class Pose:
    step: int
    t: float
    x: float
    y: float
    psi: float
    u: float
    v: float
    r: float


def vehicle_size(mission, name: str) -> dict:
    """Name, length and diameter of the vehicle named `name` in the keys: its `[[vehicles]]` entry's
    type or the mission's vehicle (`logfile.vehicle_spec`), else a library vehicle of that name,
    else a generic 2 m UUV."""
    from nearsub.common.physics.vehicles import Vehicle, get_vehicle
    from nearsub.common.runtime.logfile import vehicle_spec

    spec = vehicle_spec(None if mission is None else mission.model_dump(mode="json"), name)
    try:
        model = Vehicle.model_validate(spec) if isinstance(spec, dict) else get_vehicle(spec or name)
    except (KeyError, ValueError):
        return {"name": name, "length": 2.0, "diameter": 0.3}
    return {"name": name, "length": model.length, "diameter": model.diameter}


@dataclass
class Track:
    """One vehicle's poses, trail, forces and helm progress, each sorted by simulated time."""

    name: str
    length: float
    diameter: float
    poses: list[Pose] = field(default_factory=list)
    pose_times: list[float] = field(default_factory=list)
    trail: list[tuple[float, float, float]] = field(default_factory=list)  # (t, x, y)
    trail_times: list[float] = field(default_factory=list)
    forces: list[Forces] = field(default_factory=list)
    force_times: list[float] = field(default_factory=list)
    helm: list[HelmProgress] = field(default_factory=list)
    helm_times: list[float] = field(default_factory=list)


@dataclass
class SceneModel:
    """Accumulates a run's messages; `frame(t)` is the picture at simulated time t (latest if None).

    Each vehicle named in the keys has its own `Track`; a message fed without a vehicle belongs to
    the mission's (single) vehicle. The frame's `vehicles` lists every vehicle, sorted by name;
    its `vehicle`, `trail`, `forces` and status are those of the first.

    `trail_spacing` [m]: a trail point is kept each time a UUV has moved that far (a stable,
    zoom-independent trail whose size grows with the distance run, not with the step count).
    """

    length: float = 2.0
    diameter: float = 0.3
    force_reference: float = 100.0
    requested_warp: float | None = None
    trail_spacing: float | None = None
    mission: Any = None
    default_vehicle: str = "uuv"
    tracks: dict[str, Track] = field(default_factory=dict)
    events: list[dict] = field(default_factory=list)
    event_times: list[float] = field(default_factory=list)
    end: MissionEnd | None = None
    paused: bool | None = None
    _wall: deque = field(default_factory=lambda: deque(maxlen=400))  # (wall, sim t) samples

    @classmethod
    def for_mission(cls, mission) -> SceneModel:
        if mission is None:
            return cls()
        first = mission.members()[0]  # the vehicle a message without a vehicle in its key belongs to
        return cls(
            length=first.vehicle_model.length,
            diameter=first.vehicle_model.diameter,
            force_reference=force_reference(mission),
            requested_warp=mission.warp,
            mission=mission,
            default_vehicle=first.vehicle_name,
        )

    def track(self, name: str | None) -> Track:
        name = self.default_vehicle if name is None else name
        if name not in self.tracks:
            if name == self.default_vehicle:
                size = {"length": self.length, "diameter": self.diameter}
            else:
                size = vehicle_size(self.mission, name)
            self.tracks[name] = Track(name, size["length"], size["diameter"])
            self.tracks = dict(sorted(self.tracks.items()))
        return self.tracks[name]

    @property
    def primary(self) -> Track | None:
        """The first vehicle (by name) that has a pose, else the first."""
        return next((t for t in self.tracks.values() if t.poses), next(iter(self.tracks.values()), None))

    @property
    def poses(self) -> list[Pose]:
        return self.primary.poses if self.primary is not None else []

    def spacing(self, track: Track) -> float:
        return self.trail_spacing if self.trail_spacing is not None else max(0.25 * track.length, 0.2)

    # -- input --------------------------------------------------------------------------------
    def feed(self, message: Message, wall: float | None = None, vehicle: str | None = None) -> None:
        """Take one decoded message of `vehicle` (None: the mission's vehicle; events and the end
        are the mission's); `wall` (monotonic seconds) when it arrived, for the achieved warp
        (live runs only)."""
        if isinstance(message, State):
            self._add_pose(self.track(vehicle), message, wall)
        elif isinstance(message, Forces):
            track = self.track(vehicle)
            if not _has_time(track.force_times, message.t):
                _insert(track.force_times, track.forces, message.t, message)
        elif isinstance(message, HelmProgress):
            track = self.track(vehicle)
            if not _has_time(track.helm_times, message.t):
                _insert(track.helm_times, track.helm, message.t, message)
        elif isinstance(message, Event):
            self._add_event(message, vehicle)
        elif isinstance(message, MissionEnd):
            if self.end is None:
                self.end = message

    def _add_pose(self, track: Track, state: State, wall: float | None) -> None:
        if _has_time(track.pose_times, state.t):
            return  # seen twice: from the log read at start and from the bus
        pose = Pose(state.step, state.t, state.x, state.y, state.psi, state.u, state.v, state.r)
        if track.poses and state.t < track.pose_times[-1]:  # out of order (rare): keep the list sorted
            index = bisect.bisect_right(track.pose_times, state.t)
            track.poses.insert(index, pose)
            track.pose_times.insert(index, state.t)
        else:
            track.poses.append(pose)
            track.pose_times.append(state.t)
        trail = track.trail
        if not trail or math.hypot(state.x - trail[-1][1], state.y - trail[-1][2]) >= self.spacing(track):
            if not trail or state.t >= track.trail_times[-1]:
                trail.append((state.t, state.x, state.y))
                track.trail_times.append(state.t)
        if wall is not None and track is self.primary:
            self._wall.append((wall, state.t))

    def _add_event(self, event: Event, vehicle: str | None) -> None:
        if event.kind not in LISTED_EVENTS:
            return
        x, y = event.data.get("x"), event.data.get("y")
        if not (isinstance(x, (int, float)) and isinstance(y, (int, float))):
            pose = self.pose_at(event.t, vehicle)
            x, y = (pose.x, pose.y) if pose is not None else (None, None)
        item = {
            "t": round(event.t, 3),
            "step": event.step,
            "kind": event.kind,
            "detail": event.detail,
            "source": event.source,
            "vehicle": vehicle,
            "x": None if x is None else round(float(x), 3),
            "y": None if y is None else round(float(y), 3),
            "marked": event.kind in MARKED_EVENTS,
        }
        if item in self.events[bisect.bisect_left(self.event_times, event.t) :]:
            return  # seen twice: from the log read at start and from the bus
        _insert(self.event_times, self.events, event.t, item)

    # -- queries ------------------------------------------------------------------------------
    def pose_at(self, t: float | None, vehicle: str | None = None) -> Pose | None:
        track = self.primary if vehicle is None or vehicle not in self.tracks else self.tracks[vehicle]
        return None if track is None else _latest(track.pose_times, track.poses, t)

    def time_range(self) -> tuple[float, float]:
        times = [track.pose_times for track in self.tracks.values() if track.pose_times]
        if not times:
            return 0.0, 0.0
        return min(t[0] for t in times), max(t[-1] for t in times)

    def achieved_warp(self) -> float | None:
        """Simulated seconds per wall second over the last WARP_WINDOW wall seconds."""
        if len(self._wall) < 2:
            return None
        wall_end, t_end = self._wall[-1]
        first = next(((w, t) for w, t in self._wall if wall_end - w <= WARP_WINDOW), self._wall[0])
        span = wall_end - first[0]
        if span <= 0:
            return None
        return (t_end - first[1]) / span

    def _vehicle_frame(self, track: Track, t: float | None) -> dict:
        """One vehicle at t: its outline at its heading (None before its first state), trail,
        forces and helm status."""
        pose = _latest(track.pose_times, track.poses, t)
        until = t + TIME_SLACK if t is not None else math.inf
        trail_end = bisect.bisect_right(track.trail_times, until)
        trail = [[round(x, 3), round(y, 3)] for _, x, y in track.trail[:trail_end]]
        vehicle = None
        if pose is not None:
            if not trail or trail[-1] != [round(pose.x, 3), round(pose.y, 3)]:
                trail.append([round(pose.x, 3), round(pose.y, 3)])
            ox, oy = uuv_outline(pose.x, pose.y, pose.psi, track.length, track.diameter, UUV_POINTS)
            vehicle = {
                "name": track.name,
                "step": pose.step,
                "t": pose.t,
                "x": pose.x,
                "y": pose.y,
                "psi": pose.psi,
                "heading_deg": round(math.degrees(pose.psi), 2),
                "speed": round(math.hypot(pose.u, pose.v), 3),
                "length": track.length,
                "outline": _points(ox, oy),
            }
        helm = _latest(track.helm_times, track.helm, t)
        return {
            "name": track.name,
            "pose": pose,
            "vehicle": vehicle,
            "trail": trail,
            "forces": self._force_frame(track, t, pose),
            "behaviour": None if helm is None else helm.behaviour,
            "leg": None if helm is None else helm.leg,
            "waypoints_reached": None if helm is None else helm.waypoints_reached,
            "cross_track": None if helm is None else round(helm.cross_track, 3),
        }

    def frame(self, t: float | None = None, now: float | None = None) -> dict:
        """The picture at simulated time t (None: the newest). `now` (monotonic wall time) lets
        a live view report a warp of 0 once the states stop (paused, ended)."""
        vehicles = [self._vehicle_frame(track, t) for track in self.tracks.values()]
        primary = self.primary
        main = next((v for v in vehicles if primary is not None and v["name"] == primary.name), None)
        pose = None if main is None else main.pop("pose")
        for item in vehicles:
            item.pop("pose", None)
        until = t + TIME_SLACK if t is not None else math.inf
        events_end = bisect.bisect_right(self.event_times, until)
        events = self.events[:events_end]
        end = None
        if self.end is not None:
            # The end is labelled with the step after the last state: show it from that state on.
            last_pose = self.time_range()[1] if self.tracks else math.inf
            if t is None or until >= min(self.end.t, last_pose):
                end = self.end
        warp = self.achieved_warp() if t is None else None
        if warp is not None and now is not None and self._wall and now - self._wall[-1][0] > 1.0:
            warp = 0.0  # no state for a second of wall time: the run is not advancing
        return {
            "type": "frame",
            "t": pose.t if pose is not None else (t or 0.0),
            "vehicle": None if main is None else main["vehicle"],
            "trail": [] if main is None else main["trail"],
            "forces": None if main is None else main["forces"],
            "vehicles": vehicles,
            "events": events[-MAX_LISTED:],
            "event_count": len(events),
            "status": {
                "t": None if pose is None else round(pose.t, 3),
                "step": None if pose is None else pose.step,
                "requested_warp": self.requested_warp,
                "achieved_warp": None if warp is None else round(warp, 3),
                "behaviour": None if main is None else main["behaviour"],
                "leg": None if main is None else main["leg"],
                "waypoints_reached": None if main is None else main["waypoints_reached"],
                "cross_track": None if main is None else main["cross_track"],
                "outcome": None if end is None else end.outcome,
                "reason": None if end is None else end.reason,
                "paused": self.paused,
            },
            "range": list(self.time_range()),
        }

    def _force_frame(self, track: Track, t: float | None, pose: Pose | None) -> dict | None:
        """The applied interaction (weight times the surrogate's forces) as an arrow from the UUV's
        CB in the submarine frame, and the yaw moment as a gauge fraction in [-1, 1]."""
        forces = _latest(track.force_times, track.forces, t)
        if forces is None:
            return None
        w = forces.weight
        fx, fy, n = w * forces.X_s, w * forces.Y_s, w * forces.N_s
        out: dict[str, Any] = {
            "X_s": round(fx, 3),
            "Y_s": round(fy, 3),
            "N_s": round(n, 3),
            "weight": round(w, 4),
            "in_domain": forces.in_domain,
            "constraints_ok": forces.constraints_ok,
            "arrow": None,
            "moment_fraction": 0.0,
        }
        if pose is not None:
            scale = track.length / self.force_reference  # metres of arrow per newton
            c, s = math.cos(pose.psi), math.sin(pose.psi)
            ex, ey = fx * c - fy * s, fx * s + fy * c
            out["arrow"] = [_round([pose.x, pose.y]), _round([pose.x + ex * scale, pose.y + ey * scale])]
            fraction = n / (self.force_reference * track.length)
            out["moment_fraction"] = round(max(-1.0, min(1.0, fraction)), 4)
        return out


def _insert(times: list[float], items: list, t: float, item) -> None:
    """Append keeping `times` sorted (messages arrive nearly in order)."""
    if not times or t >= times[-1]:
        times.append(t)
        items.append(item)
    else:
        index = bisect.bisect_right(times, t)
        times.insert(index, t)
        items.insert(index, item)


def _has_time(times: list[float], t: float) -> bool:
    index = bisect.bisect_left(times, t)
    return index < len(times) and times[index] == t


TIME_SLACK = 1e-6  # [s], far below any step


def _latest(times: list[float], items: list, t: float | None):
    """The newest item at or before t (the newest of all when t is None). Times are k dt in
    binary and a page's t is decimal (11.7 against 11.700000000000001): 1 us of slack."""
    if not items:
        return None
    if t is None:
        return items[-1]
    index = bisect.bisect_right(times, t + TIME_SLACK)
    return items[index - 1] if index else None


def feed_payload(model: SceneModel, key: str, payload: bytes, wall: float | None = None) -> bool:
    """Decode one bus or log payload by its key and feed it; False for keys the picture does not
    use and for malformed payloads (the receiving apps report those; the viewer only watches)."""
    from nearsub.common.runtime.messages import MessageError, decode, model_for_key

    owner = vehicle_of(key)
    message_type = model_for_key(key)
    if message_type not in (State, Forces, HelmProgress, Event, MissionEnd):
        return False
    try:
        message = decode(payload, message_type, key)
    except MessageError:
        return False
    model.feed(message, wall, None if owner is None else owner[0])
    return True
