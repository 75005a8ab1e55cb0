"""What a fleet mission shows: per vehicle, when it departed and completed and how close it came
to the hull; per pair, how close the vehicles came to each other (docs/scenarios/launch_two.md)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nearsub.common.analysis import approach
from nearsub.common.mission.schema import Mission
from nearsub.common.physics import proximity
from nearsub.common.runtime.lifecycle import InProcessResult


@dataclass
class VehicleFigures:
    name: str
    type: str
    phase_times: dict[str, float]  # first time each value of PHASE was posted [s]
    completed_at: float | None  # the helm's last waypoint reached [s]
    track: np.ndarray  # (n, 3): x, y, psi of every state
    times: np.ndarray  # (n,): their simulated times [s]
    hull_clearance: np.ndarray  # (n,): the outline's clearance from the hull [m]

    @property
    def closest_hull(self) -> float:
        return float(np.min(self.hull_clearance))


@dataclass
class FleetFigures:
    outcome: str
    reason: str
    duration: float
    vehicles: list[VehicleFigures]
    closest_pair: dict[tuple[str, str], tuple[float, float]] = field(default_factory=dict)  # (clearance, t)
    encounter_events: list[str] = field(default_factory=list)

    def vehicle(self, name: str) -> VehicleFigures:
        return next(v for v in self.vehicles if v.name == name)


def fleet_figures(mission: Mission, result: InProcessResult) -> FleetFigures:
    found, tracks = [], {}
    for member in mission.members():
        name, model = member.vehicle_name, member.vehicle_model
        states = result.topic("state", name)
        track = np.array([[s.x, s.y, s.psi] for s in states])
        times = np.array([s.t for s in states])
        phases: dict[str, float] = {}
        for app, leaf, message in result.messages:
            if leaf == "events" and app == f"{name}/helm" and message.data.get("variable") == "PHASE":
                phases.setdefault(str(message.data["value"]), message.t)
        done = next((m.t for m in result.topic("helm", name) if m.complete), None)
        hull = proximity.closest_distance(track[:, 0], track[:, 1], track[:, 2], model.length, model.diameter)
        found.append(VehicleFigures(name, model.name, phases, done, track, times, hull))
        steps = np.array([s.step for s in states])
        tracks[name] = approach.Track(steps, times, *track.T, model.length, model.diameter)
    figures = FleetFigures(result.outcome, result.reason, result.steps * mission.dt, found)
    for i, a in enumerate(found):
        for b in found[i + 1 :]:
            pair = approach.pair_approach(a.name, tracks[a.name], b.name, tracks[b.name])
            figures.closest_pair[(a.name, b.name)] = (pair.clearance, pair.t)
    figures.encounter_events = [f"{e.kind} at t = {e.t:.2f} s: {e.detail}" for e in result.topic("events")]
    return figures
