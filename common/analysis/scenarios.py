"""Figures of merit of a finished mission, as the thesis reports them for its scenarios (figures
5-5, 6-2, 6-3 and 6-6): the outcome, the closest approach to the submarine, and how far and how
long the UUV strayed from its track-lines; and the scenario checks of `nearsub validate`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nearsub.common.analysis.validation import Row
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import Mission, load_mission
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


def scenario_rows(missions: Path) -> list[Row]:
    """Missions (files in `missions`) whose outcome is part of the validation: alpha with each
    vehicle, the sea-state-5 track-line of thesis figure 5-6, and the interaction scenarios."""
    rows = []
    for vehicle in ("remus100", "nps_auv_ii", "sdv"):
        mission = load_mission(missions / "alpha.toml", [f"vehicle={vehicle}"])
        result = run_mission(mission)
        reached = sum(1 for _, leaf, m in result.messages if leaf == "events" and m.kind == "waypoint")
        rows.append(
            Row(
                f"alpha mission, {vehicle}: waypoints reached",
                reached,
                6,
                0.0,
                "",
                result.outcome == "completed" and reached == 6,
                f"{result.outcome} after {result.steps * mission.dt:.1f} s (MOOS-IvP: about 446 s)",
            )
        )
    mission = load_mission(missions / "waves_ss5.toml")
    result = run_mission(mission)
    worst = max(m.cross_track for m in result.topic("helm"))
    rows.append(
        Row(
            "waves_ss5 (figure 5-6): max cross-track error",
            worst,
            None,
            None,
            "m",
            result.outcome == "completed",
            f"report only; passes if the UUV keeps the track and reaches the waypoint ({result.outcome})",
        )
    )
    return rows + interaction_scenario_rows(missions)


# Scenario missions of thesis chapters 5 and 6 and the figure each reproduces.
SCENARIOS = {
    "overtake_stern_standard": "figure 5-5, closest approach",
    "overtake_stern_nuv": "figure 6-2, closest approach",
    "octagon_standard": "figure 6-6, max cross-track",
    "octagon_modified": "figure 6-6, max cross-track",
    "lateral_approach": "figure 6-3, max cross-track on the lateral leg",
}


def interaction_scenario_rows(missions: Path) -> list[Row]:
    """The chapter 5 and 6 scenarios, each checked against the thesis's qualitative outcome."""
    figures = {
        name: scenario_figures(mission, run_mission(mission))
        for name, mission in ((name, load_mission(missions / f"{name}.toml")) for name in SCENARIOS)
    }

    def row(name: str, measured: float, unit: str, passed: bool, expected: str) -> Row:
        f = figures[name]
        note = f"{expected}; {f.outcome}, closest approach {f.closest_approach:.3f} m at x = {f.closest_at[0]:.1f} m"
        return Row(f"{name}: {SCENARIOS[name]}", measured, None, None, unit, passed, note)

    standard, nuv = figures["overtake_stern_standard"], figures["overtake_stern_nuv"]
    octagon, modified = figures["octagon_standard"], figures["octagon_modified"]
    lateral = figures["lateral_approach"]
    capture = load_mission(missions / "octagon_modified.toml").apps.helm.legs[0].capture_radius
    return [
        row("overtake_stern_standard", standard.closest_approach, "m", standard.outcome == "collision", "collision"),
        row("overtake_stern_nuv", nuv.closest_approach, "m", nuv.outcome == "completed", "no collision"),
        row("octagon_standard", octagon.max_cross_track, "m", octagon.max_cross_track > 5.0, "strays > 5 m"),
        row(
            "octagon_modified",
            modified.max_cross_track,
            "m",
            modified.waypoints_reached == 8 and modified.max_cross_track <= capture,
            f"all 8 waypoints, cross-track within the capture radius {capture:g} m",
        ),
        row(
            "lateral_approach",
            lateral.max_cross_track_per_waypoint[1],
            "m",
            lateral.max_cross_track_per_waypoint[0] <= 1.0 < lateral.max_cross_track_per_waypoint[1],
            "on track along the flow (<= 1 m), a large stray (> 1 m) across it",
        ),
    ]
