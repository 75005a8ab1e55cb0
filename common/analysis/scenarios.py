"""Figures of merit of a finished mission, as the thesis reports them for its scenarios (figures
5-5, 6-2, 6-3 and 6-6): the outcome, the closest approach to the submarine, and how far and how
long the UUV strayed from its track-lines."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nearsub.common.mission.schema import Mission
from nearsub.common.physics import proximity as events
from nearsub.common.runtime.lifecycle import InProcessResult


@dataclass(frozen=True)
class ScenarioFigures:
    outcome: str
    waypoints_reached: int
    closest_approach: float  # smallest hull-to-hull clearance [m]; <= 0 is a collision
    closest_at: tuple[float, float]  # UUV CB (x, y) there [m]
    max_cross_track: float  # [m], over the whole mission
    max_cross_track_per_waypoint: tuple[float, ...]  # [m], one per track-line flown, in order
    stray_fraction: float  # share of helm steps more than events.STRAY_LIMIT off the track-line

    def as_dict(self) -> dict:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


def scenario_figures(mission: Mission, result: InProcessResult) -> ScenarioFigures:
    """Summarise an in-process run of `mission` (the multi-process log has the same messages)."""
    states = result.topic("state")
    x, y, psi = (np.array([getattr(s, name) for s in states]) for name in ("x", "y", "psi"))
    vehicle = mission.vehicle_model
    if mission.environment.submarine:
        clearance = events.closest_distance(x, y, psi, vehicle.length, vehicle.diameter)
        worst = int(np.argmin(clearance))
        closest, closest_at = float(clearance[worst]), (float(x[worst]), float(y[worst]))
    else:
        closest, closest_at = float("inf"), (float("nan"), float("nan"))
    progress = result.topic("helm")
    cross_track = np.array([p.cross_track for p in progress])
    per_waypoint: dict[tuple[int, int], float] = {}
    for p in progress:
        key = (p.leg, p.waypoint_index)
        per_waypoint[key] = max(per_waypoint.get(key, 0.0), p.cross_track)
    reached = max((p.waypoints_reached for p in progress), default=0)
    return ScenarioFigures(
        outcome=result.outcome,
        waypoints_reached=reached,
        closest_approach=closest,
        closest_at=closest_at,
        max_cross_track=float(cross_track.max(initial=0.0)),
        max_cross_track_per_waypoint=tuple(per_waypoint[key] for key in sorted(per_waypoint)),
        stray_fraction=float(np.mean(cross_track > events.STRAY_LIMIT)) if len(cross_track) else 0.0,
    )
