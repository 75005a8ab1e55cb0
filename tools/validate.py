"""`nearsub validate`: the physics validation cases and scenario checks, run in-process.

Prints measured value, target, tolerance and PASS/FAIL per case; `--json` for machines. Exits 1
if any case fails.
"""

from __future__ import annotations

import json
from pathlib import Path

from rich.console import Console
from rich.table import Table

from nearsub.common.analysis.scenarios import scenario_figures
from nearsub.common.analysis.validation import Row, run_validation
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission

MISSIONS = Path(__file__).resolve().parents[1] / "missions"


def scenario_rows() -> list[Row]:
    """Missions whose outcome is part of the validation: alpha with each vehicle, and the
    sea-state-5 track-line of thesis figure 5-6."""
    rows = []
    for vehicle in ("remus100", "nps_auv_ii", "sdv"):
        mission = load_mission(MISSIONS / "alpha.toml", [f"vehicle={vehicle}"])
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
    mission = load_mission(MISSIONS / "waves_ss5.toml")
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
    return rows + interaction_scenario_rows()


# Scenario missions of thesis chapters 5 and 6 and the figure each reproduces.
SCENARIOS = {
    "overtake_stern_standard": "figure 5-5, closest approach",
    "overtake_stern_nuv": "figure 6-2, closest approach",
    "octagon_standard": "figure 6-6, max cross-track",
    "octagon_modified": "figure 6-6, max cross-track",
    "lateral_approach": "figure 6-3, max cross-track on the lateral leg",
}


def interaction_scenario_rows() -> list[Row]:
    """The chapter 5 and 6 scenarios, each checked against the thesis's qualitative outcome."""
    figures = {
        name: scenario_figures(mission, run_mission(mission))
        for name, mission in ((name, load_mission(MISSIONS / f"{name}.toml")) for name in SCENARIOS)
    }

    def row(name: str, measured: float, unit: str, passed: bool, expected: str) -> Row:
        f = figures[name]
        note = f"{expected}; {f.outcome}, closest approach {f.closest_approach:.3f} m at x = {f.closest_at[0]:.1f} m"
        return Row(f"{name}: {SCENARIOS[name]}", measured, None, None, unit, passed, note)

    standard, nuv = figures["overtake_stern_standard"], figures["overtake_stern_nuv"]
    octagon, modified = figures["octagon_standard"], figures["octagon_modified"]
    lateral = figures["lateral_approach"]
    capture = load_mission(MISSIONS / "octagon_modified.toml").apps.helm.legs[0].capture_radius
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


def validate_command(args) -> int:
    rows = run_validation() + scenario_rows()
    failed = [r for r in rows if not r.passed]
    if args.json:
        print(json.dumps([r.__dict__ for r in rows]))
    else:
        table = Table(title="nearsub validate")
        for column in ("case", "measured", "target", "tolerance", "unit", "result", "note"):
            table.add_column(column, overflow="fold")
        for r in rows:
            table.add_row(
                r.name,
                f"{r.measured:.4g}",
                "-" if r.target is None else f"{r.target:g}",
                "-" if r.tolerance is None else f"{r.tolerance * 100:g} %",
                r.unit,
                "[green]PASS[/]" if r.passed else "[red]FAIL[/]",
                r.note,
            )
        Console(width=160).print(table)
        print(f"{len(rows) - len(failed)} passed, {len(failed)} failed")
    return 1 if failed else 0
