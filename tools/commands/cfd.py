"""`nearsub cfd case|run|validate|report`: the RANS fidelity on OpenFOAM (docs/hydro/rans/README.md).

    nearsub cfd case --psi 4.07 -o ./suboff-4                     # write one case folder (SUBOFF)
    nearsub cfd run --suite suboff-validation --cores 2 --work-dir ./cfd-runs \\
        --export docs/hydro/rans/cases --commit                    # resumable; --scheduler for Dask
    nearsub cfd validate --from docs/hydro/rans/cases             # thesis tables 3.1/3.2
    nearsub cfd report --from ./cfd-runs
    nearsub cfd compare --from docs/hydro/rans/cases -o ./compare    # RANS vs panel HF, LF, model

The logic is in common/hydro/rans*.py; this module parses and prints.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

from ..support.arguments import integer, number
from ..support.errors import InputError
from ..support.outputs import output_file, output_folder
from ..support.schedulers import scheduler_address

DEFAULT_WORK_DIR = Path("cfd-runs")
DEFAULT_ARTEFACTS = Path("docs") / "hydro" / "rans" / "cases"


def _specs(args):
    from nearsub.common.hydro import rans, rans_campaign

    if getattr(args, "suite", None):
        specs = rans_campaign.suite(args.suite, args.turbulence)
    elif args.config is not None:
        if args.sustain_inflow:
            raise InputError("--sustain-inflow: only for a SUBOFF case (--psi)")
        specs = [
            rans.two_body_case(
                args.config, args.level, args.wall_function, args.y_plus, args.iterations, args.turbulence
            )
        ]
    else:
        specs = [
            rans.suboff_case(
                args.psi,
                args.level,
                args.wall_function,
                args.y_plus,
                args.iterations,
                args.sustain_inflow,
                args.turbulence,
            )
        ]
    intensity = rans.INFLOW_INTENSITY if args.inflow_intensity is None else args.inflow_intensity / 100.0
    ratio = rans.INFLOW_VISCOSITY_RATIO if args.inflow_viscosity_ratio is None else args.inflow_viscosity_ratio
    return [rans.with_inflow(spec, intensity, ratio) for spec in specs]


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
    print(
        "| case | mesh | model | inflow I, nu_t/nu | wall function | y+ target | mean y+ | cells | min | X [N] | X' "
        "| vs EFD | verdict |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in table["resistance"]:
        intensity, ratio = r["inflow"]
        y_plus, x, xp, error = (
            ("", "", "", "")  # a diverged case's last numbers are no answer: left blank
            if r["status"] == "diverged"
            else (
                rans_campaign.y_plus_text(r["y_plus_mean"]),
                f"{r['X_N']:.1f}",
                f"{r['Xp']:.4e}",
                f"{r['error']:+.1%}",
            )
        )
        numbers = f" {y_plus} | {r['cells']:,} | {r['minutes']:.1f} | {x} | {xp} | {error} | "
        print(
            f"| {r['case']} | {r['level']} | {r['turbulence']} | {100 * intensity:g} %, {ratio:g} | "
            f"{r['wall_function']} | {r['y_plus_target']:g} |{numbers}"
            f"{r['status']}{', meets' if r['meets'] else ''} |"
        )
    if table["gci"]:
        g = table["gci"]
        print(
            f"\nGCI (coarse/medium/fine, ratio sqrt 2; Celik et al. 2008; the order credited at most "
            f"{rans_campaign.FORMAL_ORDER:g}): observed order {g['p']:.2f}, "
            f"extrapolated X' {g['extrapolated']:.4e}, GCI_fine {g['gci_fine']:.2%}"
        )
    target = f"target GCI_fine <= {rans_campaign.GCI_TARGET:.0%}"
    stations = {s.name: s for s in rans_campaign.TWO_BODY_STATIONS}
    for study in table["two_body_gci"]:
        name = study["station"]
        print(f"\nTwo-body GCI at '{name}' {list(stations[name].row)}, meshes {study['levels']} ({target})")
        for output, g in study["outputs"].items():
            if g["p"] != g["p"]:  # NaN: no monotone convergence
                how = "oscillates" if g["ratio"] < 0 else "the change grows with refinement"
                bound = g.get("oscillation_fine", math.nan)
                half_range = f"; half the oscillation's range {bound:.2%} of the fine value" if bound == bound else ""
                print(
                    f"  {output}': no GCI: convergence ratio {g['ratio']:.2f}, {how} (not in the asymptotic range)"
                    f"{half_range}"
                )
                continue
            print(
                f"  {output}': observed order {g['p']:.2f}"
                f"{f' (GCI with {rans_campaign.FORMAL_ORDER:g})' if g['p'] > rans_campaign.FORMAL_ORDER else ''}, "
                f"convergence ratio {g['ratio']:.2f}, extrapolated {g['extrapolated']:.4e}, "
                f"GCI_fine {g['gci_fine']:.2%}{' meets' if g['meets'] else ''}"
            )
    if not table["two_body_gci"]:
        print("\nTwo-body GCI: no station has its coarse, medium and fine cases all converged yet")
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


COMPARE_FILES = ("two-body-compare.md", "two-body-compare.csv", "two-body-compare.png")
INTERACTION_FILES = ("two-body-interaction.md", "two-body-interaction.csv", "two-body-interaction.png")


def _compare_markdown(rows: list[dict], summary: dict, fidelities) -> list[str]:
    """The side-by-side table (x 1e-3) and the summary as markdown lines."""
    import numpy as np

    note = (
        "Values x 1e-3; differences are the fidelity minus RANS. X' > 0 forward, Y' > 0 away from the submarine, "
        "N' > 0 bow away; the mean absolute differences (MAE) below are x 1e-3 too."
    )
    head = "| station | R_long | R_lat | psi | D/d | L/D | held out | cells | min | out | RANS | "
    head += " | ".join(f"{f} | {f} - RANS" for f in fidelities) + " |"
    lines = [note, "", head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        r_long, r_lat, _, psi, d_ratio, ld_ratio = r["inputs"]
        for k, out in enumerate(("X'", "Y'", "N'")):
            lead = (
                f"| {r['station'] or r['case']} | {r_long:g} | {r_lat:g} | {psi:g} | {d_ratio:g} | {ld_ratio:g} | "
                f"{'yes' if r['held_out'] else ''} | {r['cells']:,} | {r['minutes']:.0f} |"
                if k == 0
                else "| | | | | | | | | |"
            )
            cells = " | ".join(f"{r[f][k] * 1e3:+.3f} | {r[f + ' - RANS'][k] * 1e3:+.3f}" for f in fidelities)
            lines.append(f"{lead} {out} | {r['RANS'][k] * 1e3:+.3f} | {cells} |")
    lines += [
        "",
        "| fidelity | MAE X' | Y' | N' | held out: X' | Y' | N' | sign agrees X' | Y' | N' |",
        "|---" * 10 + "|",
    ]
    for name, s in summary.items():
        mae, held, sign = (np.array(s[k]) * f for k, f in (("mae", 1e3), ("mae_held_out", 1e3), ("sign_agrees", 1)))
        lines.append(
            f"| {name} | "
            + " | ".join(f"{v:.3f}" for v in (*mae, *held))
            + " | "
            + " | ".join(f"{v:.0%}" for v in sign)
            + " |"
        )
    return lines


def _compare_figure(rows: list[dict], fidelities, path: Path, title: str | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from nearsub.common.analysis.rans_comparison import CORRECTED, SCALED

    fig, axes = plt.subplots(3, 1, figsize=(max(8, 0.45 * len(rows) + 3), 9), sharex=True)
    x = np.arange(len(rows))
    markers = {
        "RANS": ("k", "o"),
        "panel HF": ("tab:blue", "s"),
        "LF": ("tab:green", "^"),
        "model": ("tab:orange", "D"),
        "flown": ("tab:red", "x"),
        SCALED: ("tab:purple", "+"),
        CORRECTED: ("tab:brown", "*"),
    }
    for k, (ax, out) in enumerate(zip(axes, ("X'", "Y'", "N'"), strict=True)):
        for name in ("RANS", *fidelities):
            colour, marker = markers[name]
            ax.plot(x, [r[name][k] * 1e3 for r in rows], marker, color=colour, label=name, ls="none", mfc="none")
        ax.axhline(0.0, color="0.7", lw=0.5)
        ax.set_ylabel(f"{out} x 1e3")
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=len(fidelities) + 1, fontsize=8)
    axes[-1].set_xticks(
        x,
        [
            (r["station"] or r["case"])
            + ("" if r["level"] == "medium" else f" ({r['level']})")
            + (" *" if r["held_out"] else "")
            for r in rows
        ],
        rotation=70,
        ha="right",
        fontsize=7,
    )
    axes[0].set_title(
        (title or "Two-body stations")
        + ": RANS (OpenFOAM) against the panel HF, the LF and the shipped model's (* held out)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _compare_csv(rows: list[dict], fidelities, path: Path) -> None:
    import csv

    from nearsub.common.analysis import rans_comparison
    from nearsub.common.hydro import rans

    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(
            [
                "case",
                "station",
                "held_out",
                *rans.CONFIGURATION,
                "level",
                "cells",
                "minutes",
                "output",
                "RANS",
                *(c for name in fidelities for c in (name, f"{name} - RANS")),
            ]
        )
        for r in rows:
            for k, o in enumerate(rans_comparison.OUTPUTS):
                writer.writerow(
                    [
                        r["case"],
                        r["station"],
                        r["held_out"],
                        *r["inputs"],
                        r["level"],
                        r["cells"],
                        f"{r['minutes']:.1f}",
                        f"{o}'",
                        f"{r['RANS'][k]:.6e}",
                        *(f"{r[c][k]:.6e}" for name in fidelities for c in (name, f"{name} - RANS")),
                    ]
                )


def compare_command(args) -> int:
    import numpy as np

    from nearsub.common.analysis import rans_comparison

    out = output_folder(Path(args.out), "-o")
    targets = [out / name for name in COMPARE_FILES]
    if not args.force and (busy := [t for t in (*targets, *(out / n for n in INTERACTION_FILES)) if t.exists()]):
        raise InputError(f"-o {out}: {busy[0].name} exists; give a new folder or --force")
    found = _found(args)
    results = rans_comparison.two_body_converged(found)
    if not results:
        raise InputError(f"--from {' '.join(map(str, args.sources or []))}: no converged two-body case to compare")
    fidelities = (*rans_comparison.FIDELITIES, rans_comparison.SCALED)
    values = rans_comparison.fidelity_values(np.array([r.inputs for r in results]))
    rho = rans_comparison.fitted_scale(rans_comparison.comparison_rows(results, values))
    values[rans_comparison.SCALED] = values["panel HF"] * rho
    rows = rans_comparison.comparison_rows(results, values)
    summary = rans_comparison.comparison_summary(rows, fidelities)
    out.mkdir(parents=True, exist_ok=True)
    _compare_figure(rows, fidelities, targets[2])  # first: a failure while drawing leaves no table behind
    skipped = sorted(r.case_id for r in found if r.kind == "two-body" and not r.convergence.usable)
    lines = _compare_markdown(rows, summary, fidelities)
    trained = sum(1 for r in rows if not r["held_out"] and r["level"] == "medium")
    lines += [
        "",
        f"{rans_comparison.SCALED}: the panel HF times rho = {rho[0]:.3f} (X'), {rho[1]:.3f} (Y'), {rho[2]:.3f} (N'), "
        f"fitted by least squares to RANS on the {trained} medium-mesh stations not held out; its held-out "
        "MAE is a fair test of the fit.",
    ]
    if skipped:
        lines += ["", "Not compared (not converged): " + ", ".join(skipped)]
    targets[0].write_text("\n".join(lines) + "\n")
    _compare_csv(rows, fidelities, targets[1])
    interaction_lines = _interaction_compare(found, out)
    if interaction_lines:
        (out / INTERACTION_FILES[0]).write_text("\n".join(interaction_lines) + "\n")
        targets += [out / name for name in INTERACTION_FILES]
    print("\n".join(lines))
    print(f"wrote {', '.join(str(t) for t in targets)}")
    return 0


def _interaction_inputs(found):
    """The converged two-body results that have their UUV alone, RANS's interaction there and the
    product's fidelities' (`rans_comparison.interaction_values`, without a correction)."""
    import numpy as np

    from nearsub.common.analysis import rans_comparison

    results = rans_comparison.two_body_converged(found)
    truth = rans_comparison.rans_interaction(results, rans_comparison.uuv_alone(found))
    keep = np.isfinite(truth).all(axis=1)
    results, truth = [r for r, k in zip(results, keep, strict=True) if k], truth[keep]
    return results, truth


def correct_command(args) -> int:
    """Fit the viscous correction of a model to the RANS stations kept for training."""

    from nearsub.common.analysis import rans_comparison
    from nearsub.common.surrogate import viscous
    from nearsub.common.surrogate.model import default_model_path, load_surrogate
    from nearsub.common.surrogate.modelfile import ModelFileError

    source = Path(args.model) if args.model else default_model_path()
    out = output_file(args.out, "-o", source=source, source_is="the model it reads")
    if out.exists() and not args.force:
        raise InputError(f"-o {out}: exists; give a new file or --force")
    try:
        model = load_surrogate(source)
    except (ModelFileError, OSError) as exc:
        raise InputError(f"--model {source}: {exc}") from None
    if model.kind != "lf_in_loop":
        raise InputError(f"--model {source}: of kind {model.kind!r}; a correction needs an LF-in-the-loop model")
    found = _found(args)
    results, truth = _interaction_inputs(found)
    rows, target, ids = rans_comparison.correction_training(results, truth)
    if len(ids) < 4:
        raise InputError(
            f"--from {' '.join(map(str, args.sources or []))}: {len(ids)} training station(s) with their UUV alone; "
            "a correction needs at least 4 (nearsub cfd run --suite two-body, then --suite uuv-alone)"
        )
    flown = rans_comparison.flown_increment(rows, model)
    meta = {
        "surrogate_model_id": model.model_id,
        "surrogate_model": str(source),
        "stations": ids,
        "command": "nearsub cfd correct " + " ".join(sys.argv[3:]),
    }
    correction = viscous.fit(rows, target, flown, meta)
    viscous.save(out, correction)
    print(f"fitted on {len(ids)} RANS stations (medium mesh, not held out) for model {model.model_id}")
    print(f"{'output':7} {'form':9} " + " ".join(f"{'LOO MAE ' + f:>16}" for f in viscous.FORMS))
    for j, name in enumerate(("X'", "Y'", "N'")):
        errors = " ".join(f"{correction.meta['loo_mae'][f][j]:16.3e}" for f in viscous.FORMS)
        print(f"{name:7} {correction.meta['forms'][j]:9} {errors}")
    print(f"wrote {out}")
    return 0


def _interaction_compare(found, out: Path) -> list[str]:
    """The interaction alone at the stations with a UUV-alone case: markdown lines, and the CSV
    and figure in `out` (INTERACTION_FILES)."""
    import numpy as np

    from nearsub.common.analysis import rans_comparison
    from nearsub.common.surrogate.interaction import viscous_correction
    from nearsub.common.surrogate.model import load_surrogate

    model = load_surrogate()
    results, truth = _interaction_inputs(found)
    if not results:
        return []
    correction = viscous_correction(model)
    values = rans_comparison.interaction_values(np.array([r.inputs for r in results]), model, correction)
    fidelities = tuple(values)
    rows = rans_comparison.comparison_rows(results, values, truth)
    summary = rans_comparison.comparison_summary(rows, fidelities)
    _compare_figure(rows, fidelities, out / INTERACTION_FILES[2], "Interaction alone (each station less its UUV alone)")
    _compare_csv(rows, fidelities, out / INTERACTION_FILES[1])
    return _compare_markdown(rows, summary, fidelities)


def cfd_command(args) -> int:
    from nearsub.common.hydro.rans import CaseError

    commands = {
        "case": case_command,
        "run": run_command,
        "validate": validate_command,
        "report": report_command,
        "compare": compare_command,
        "correct": correct_command,
    }
    try:
        return commands[args.cfd_command](args)
    except CaseError as exc:
        print(f"nearsub cfd {args.cfd_command}: {exc}", file=sys.stderr)
        return 2


def _from_argument(p) -> None:
    p.add_argument(
        "--from",
        dest="sources",
        nargs="+",
        help=f"folders of finished cases (default {DEFAULT_WORK_DIR} and {DEFAULT_ARTEFACTS})",
    )


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
        which.add_argument(
            "--suite", help="a named set of cases: suboff-validation, two-body, two-body-grid, uuv-alone, smoke"
        )
    p.add_argument("--level", default="medium", help="mesh: smoke, coarse, medium (default), fine")
    p.add_argument("--wall-function", default="nutk", help="nutk (default) or spalding")
    p.add_argument(
        "--y-plus",
        type=number(minimum=1.0, maximum=300.0),
        default=50.0,
        help="target y+ of the first cell (default 50)",
    )
    p.add_argument("--iterations", type=integer(minimum=10), help="SIMPLE iterations at most (default: the level's)")
    p.add_argument(
        "--sustain-inflow",
        action="store_true",
        help="SUBOFF: keep the inflow turbulence from decaying before the bow (SST sustaining terms)",
    )
    p.add_argument(
        "--turbulence",
        default="sst",
        help="the turbulence model, sst (k-omega SST, default) or komega (Wilcox's k-omega, the thesis's)",
    )
    p.add_argument(
        "--inflow-intensity",
        type=number(),
        metavar="PERCENT",
        help="turbulence intensity at the inlet [%%] (default 1)",
    )
    p.add_argument(
        "--inflow-viscosity-ratio",
        type=number(),
        help="eddy-viscosity ratio nu_t/nu at the inlet (default 10)",
    )
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
        _from_argument(t)
        t.add_argument("--json", action="store_true")
    t = sub.add_parser("compare", help="two-body stations: RANS against the panel HF, the LF and the shipped model")
    _from_argument(t)
    t.add_argument("-o", "--out", required=True, help="folder for the table (.md, .csv) and the figure (.png)")
    t.add_argument("--force", action="store_true", help="replace the files of an earlier comparison in --out")
    t = sub.add_parser("correct", help="fit a model's viscous correction to the RANS stations kept for training")
    _from_argument(t)
    t.add_argument("--model", help="the LF-in-the-loop model whose increment it corrects (default: the shipped model)")
    t.add_argument(
        "-o",
        "--out",
        required=True,
        help="the correction file to write (.json); use it next to the model as <stem>-viscous.json",
    )
    t.add_argument("--force", action="store_true", help="replace an existing file")
    p.set_defaults(func=cfd_command)
