"""`nearsub validate [MISSION ...]`: check mission files without running them, or, with none, the
physics validation cases and scenario checks, run in-process.

A mission (a file, or a shipped mission's name) is read with its includes and `--set` overrides
and validated as `launch` would: one line per mission, `ok` and what it holds, or the error
naming the file, field and value (with the field names a misspelt one may stand for); exit 2 if
any is bad. The physics suite prints measured value, target, tolerance and PASS/FAIL per case;
`--json` for machines. Exits 1 if any case fails.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..support.errors import InputError
from ..support.missions import add_shipped_completion

MISSIONS = Path(__file__).resolve().parents[2] / "missions"


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("validate")
    missions = p.add_argument(
        "missions",
        nargs="*",
        metavar="MISSION",
        help="mission files (or shipped missions' names) to check without running them; none: the physics suite",
    )
    add_shipped_completion(missions)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a mission setting")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=validate_command)


def validate_command(args) -> int:
    if args.missions:
        return check_missions(args.missions, args.set, args.json)
    if args.set:
        raise InputError("--set: give the MISSION files it overrides (the physics suite takes none)")
    return physics_suite(args)


def check_missions(targets: list[str], overrides: list[str], as_json: bool) -> int:
    """One line per mission: what it holds, or why it cannot be launched; 2 if any cannot."""
    from nearsub.common.mission.schema import MissionError, load_mission, mission_path

    bad = 0
    for target in targets:
        try:
            path = mission_path(target)
            mission = load_mission(path, overrides)
        except MissionError as exc:
            bad += 1
            print(
                json.dumps({"mission": target, "ok": False, "error": str(exc)})
                if as_json
                else f"nearsub validate: {exc}",
                file=sys.stderr,
            )
            continue
        vehicles = ", ".join(
            f"{m.vehicle_name} ({m.vehicle_model.name})" if mission.fleet else m.vehicle_model.name
            for m in mission.members()
        )
        near = "near a submarine" if mission.environment.submarine else "no submarine"
        steps = f"{mission.time_limit:g} s in steps of {mission.dt:g} s"
        text = f"{path}: ok: mission {mission.name}, {vehicles}, {near}, {steps}"
        print(json.dumps({"mission": target, "file": str(path), "ok": True, "name": mission.name}) if as_json else text)
    return 2 if bad else 0


def physics_suite(args) -> int:
    from rich.console import Console
    from rich.table import Table

    from nearsub.common.analysis.scenarios import scenario_rows
    from nearsub.common.analysis.validation import run_validation

    rows = run_validation() + scenario_rows(MISSIONS)
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
