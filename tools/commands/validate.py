"""`nearsub validate`: the physics validation cases and scenario checks, run in-process.

Prints measured value, target, tolerance and PASS/FAIL per case; `--json` for machines. Exits 1
if any case fails.
"""

from __future__ import annotations

import json
from pathlib import Path

MISSIONS = Path(__file__).resolve().parents[2] / "missions"


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("validate")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=validate_command)


def validate_command(args) -> int:
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
