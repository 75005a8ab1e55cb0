"""`nearsub cfd case|run|validate|report`: the RANS fidelity on OpenFOAM (docs/hydro/rans/README.md).

    nearsub cfd case --psi 4.07 -o ./suboff-4                     # write one case folder (SUBOFF)
    nearsub cfd run --suite suboff-validation --cores 2 --work-dir ./cfd-runs \\
        --export docs/hydro/rans/cases --commit                    # resumable; --scheduler for Dask
    nearsub cfd validate --from docs/hydro/rans/cases             # thesis tables 3.1/3.2
    nearsub cfd report --from ./cfd-runs

The logic is in common/hydro/rans*.py; this module parses and prints.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..support.arguments import integer, number
from ..support.errors import InputError
from ..support.outputs import output_folder
from ..support.schedulers import scheduler_address

DEFAULT_WORK_DIR = Path("cfd-runs")
DEFAULT_ARTEFACTS = Path("docs") / "hydro" / "rans" / "cases"


def _specs(args):
    from nearsub.common.hydro import rans, rans_campaign

    if getattr(args, "suite", None):
        return rans_campaign.suite(args.suite)
    if args.config is not None:
        return [rans.two_body_case(args.config, args.level, args.wall_function, args.y_plus, args.iterations)]
    return [rans.suboff_case(args.psi, args.level, args.wall_function, args.y_plus, args.iterations)]


def case_command(args) -> int:
    from nearsub.common.hydro import rans

    (spec,) = _specs(args)
    out = Path(args.out) if args.out else DEFAULT_WORK_DIR / spec.case_id
    output_folder(out, "-o")
    if out.exists() and any(out.iterdir()):
        raise InputError(f"-o {out}: exists and is not empty; give a new folder")
    rans.write_case(spec, out, args.cores)
    dom = rans.domain(spec)
    print(
        f"wrote {out}: {spec.case_id}, background {dom.cells} cells of {dom.background:.3g} m, surface levels "
        f"{dom.surface_levels}, first layer {rans.first_layer_thickness(spec) * 1e3:.3g} mm"
    )
    return 0


def run_command(args) -> int:
    from nearsub.common.hydro import rans, rans_campaign

    specs = _specs(args)
    if args.scheduler is None and (missing := rans.openfoam_missing()):
        raise InputError(missing)
    work_dir = output_folder(Path(args.work_dir), "--work-dir")
    export_dir = output_folder(Path(args.export), "--export") if args.export else None
    if args.commit and export_dir is None:
        raise InputError("--commit: needs --export (the folder in the repository the artefacts go to)")
    pending = [s.case_id for s in rans_campaign.unfinished(specs, work_dir, export_dir)]
    print(
        f"{len(specs) - len(pending)} of {len(specs)} case(s) finished; running {len(pending)}: {', '.join(pending)}",
        flush=True,
    )
    refused = []

    def done(case_id: str, outcome: dict) -> None:
        if "error" in outcome:
            refused.append(case_id)
            print(f"{case_id}: refused: {outcome['error']}", flush=True)
            return
        result = rans.Result.from_json(outcome)
        if not result.convergence.usable:
            refused.append(case_id)
        print(result.line() + ("" if result.convergence.usable else f" ({result.convergence.reason})"), flush=True)

    try:
        rans_campaign.run_cases(
            specs,
            work_dir,
            args.cores,
            scheduler=args.scheduler,
            export_dir=export_dir,
            commit=args.commit,
            on_done=done,
        )
    except OSError as exc:  # a scheduler that cannot be reached, a work folder that cannot be written
        raise InputError(str(exc)) from None
    return 2 if refused else 0


def _found(args):
    from nearsub.common.hydro import rans_campaign

    folders = [Path(f) for f in args.sources] if args.sources else [DEFAULT_WORK_DIR, DEFAULT_ARTEFACTS]
    for folder in folders:
        if args.sources and not folder.is_dir():
            raise InputError(f"--from {folder}: no such folder")
    return rans_campaign.results(f for f in folders if f.is_dir())


def validate_command(args) -> int:
    from nearsub.common.hydro import rans, rans_campaign

    table = rans_campaign.validation_rows(_found(args))
    if args.json:
        print(json.dumps(table, indent=1))
        return 0
    print(
        f"SUBOFF resistance at 3.05 m/s against thesis table 3.1 (EFD X = {rans.TABLE_3_1_EFD_X} N, "
        f"X' = {rans.TABLE_3_1_EFD_XPRIME:.3g}); target |error| <= {rans_campaign.RESISTANCE_TARGET:.0%}"
    )
    print("| case | mesh | wall function | y+ target | mean y+ | cells | min | X [N] | X' | vs EFD | verdict |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in table["resistance"]:
        print(
            f"| {r['case']} | {r['level']} | {r['wall_function']} | {r['y_plus_target']:g} | {r['y_plus_mean']:.0f} | "
            f"{r['cells']:,} | {r['minutes']:.1f} | {r['X_N']:.1f} | {r['Xp']:.4e} | {r['error']:+.1%} | "
            f"{r['status']}{', meets' if r['meets'] else ''} |"
        )
    if table["gci"]:
        g = table["gci"]
        print(
            f"\nGCI (coarse/medium/fine, ratio sqrt 2; Celik et al. 2008): observed order {g['p']:.2f}, "
            f"extrapolated X' {g['extrapolated']:.4e}, GCI_fine {g['gci_fine']:.2%}"
        )
    print(
        "\nSUBOFF drift against thesis table 3.2 (x 1e-3; errors against EFD; targets: X', N' within 10 %, "
        "Y' within 10 % at 4.07 and 6.03 deg)"
    )
    print(
        "| case | psi | X' | Y' | N' | EFD X' | Y' | N' | err X' | Y' | N' | thesis CFD X' | Y' | N' "
        "| cells | min | verdict |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in table["drift"]:
        o, e, err, c = r["ours"], r["efd"], r["error"], r["thesis_cfd"]
        meets = {True: ", meets", False: ", misses", None: ""}[r["meets"]]
        print(
            f"| {r['case']} | {r['psi']:.2f} | {o[0]:.3f} | {o[1]:.3f} | {o[2]:.3f} | "
            f"{e[0]:.3f} | {e[1]:.3f} | {e[2]:.3f} | "
            f"{err[0]:+.1%} | {err[1]:+.1%} | {err[2]:+.1%} | {c[0]:.3f} | {c[1]:.3f} | {c[2]:.3f} | "
            f"{r['cells']:,} | {r['minutes']:.1f} | {r['status']}{meets} |"
        )
    return 0


def report_command(args) -> int:
    from nearsub.common.hydro import rans_campaign

    from ..support.tables import console

    found = _found(args)
    if args.json:
        print(json.dumps([r.to_json() for r in found], indent=1))
        return 0
    from rich.table import Table

    table = Table(*rans_campaign.REPORT_COLUMNS)
    for row in rans_campaign.report_rows(found):
        table.add_row(*row)
    console().print(table)
    return 0


def cfd_command(args) -> int:
    from nearsub.common.hydro.rans import CaseError

    commands = {"case": case_command, "run": run_command, "validate": validate_command, "report": report_command}
    try:
        return commands[args.cfd_command](args)
    except CaseError as exc:
        print(f"nearsub cfd {args.cfd_command}: {exc}", file=sys.stderr)
        return 2


def _case_arguments(p, suite: bool = False) -> None:
    which = p.add_mutually_exclusive_group()
    which.add_argument(
        "--psi",
        type=number(minimum=0.0, maximum=20.0),
        default=0.0,
        help="the model-scale SUBOFF alone at this drift angle [deg] (default 0; thesis table 3.2)",
    )
    which.add_argument(
        "--config",
        type=float,
        nargs=6,
        metavar=("R_LONG", "R_LAT", "U_KN", "PSI", "D_RATIO", "LD_RATIO"),
        help="a two-body configuration in the project's order (thesis table 4.2)",
    )
    if suite:
        which.add_argument("--suite", help="a named set of cases: suboff-validation, smoke")
    p.add_argument("--level", default="medium", help="mesh: smoke, coarse, medium (default), fine")
    p.add_argument("--wall-function", default="nutk", help="nutk (default) or spalding")
    p.add_argument(
        "--y-plus",
        type=number(minimum=1.0, maximum=300.0),
        default=50.0,
        help="target y+ of the first cell (default 50)",
    )
    p.add_argument("--iterations", type=integer(minimum=10), help="SIMPLE iterations at most (default: the level's)")
    p.add_argument("--cores", type=integer(minimum=1, maximum=1024), default=1, help="MPI ranks per case (default 1)")


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("cfd", help="RANS CFD (OpenFOAM): SUBOFF validation and two-body cases")
    sub = p.add_subparsers(dest="cfd_command", required=True)
    t = sub.add_parser("case", help="write one OpenFOAM case folder")
    _case_arguments(t)
    t.add_argument("-o", "--out", help=f"case folder to write (default {DEFAULT_WORK_DIR}/<case id>)")
    t = sub.add_parser("run", help="mesh and solve cases (resumable: finished cases are skipped)")
    _case_arguments(t, suite=True)
    t.add_argument(
        "--work-dir", default=str(DEFAULT_WORK_DIR), help=f"case folders with meshes (default {DEFAULT_WORK_DIR})"
    )
    t.add_argument("--export", help=f"copy each finished case's small artefacts here (e.g. {DEFAULT_ARTEFACTS})")
    t.add_argument("--commit", action="store_true", help="git-commit each exported case as it finishes")
    t.add_argument("--scheduler", type=scheduler_address, help="run the cases as tasks on this Dask scheduler")
    for name, text in (
        ("validate", "the SUBOFF validation table (thesis tables 3.1, 3.2)"),
        ("report", "a table of the finished cases"),
    ):
        t = sub.add_parser(name, help=text)
        t.add_argument(
            "--from",
            dest="sources",
            nargs="+",
            help=f"folders of finished cases (default {DEFAULT_WORK_DIR} and {DEFAULT_ARTEFACTS})",
        )
        t.add_argument("--json", action="store_true")
    p.set_defaults(func=cfd_command)
