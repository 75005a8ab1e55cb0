"""`nearsub al-bench PROBLEM`: the thesis's active-learning comparisons, as files and tables.

The runner and its statistics are `nearsub.common.analysis.albench`; this module draws and writes.
Outputs in --out: PROBLEM.csv (MAPE (2.18) in percent per method, repeat, HF count and output),
PROBLEM.png (median and interquartile band against the number of HF samples), PROBLEM.json
(median, quartiles, mean +/- 95 % CI, the paired win rate of the reference method over each
baseline, the crossover HF counts and the wall time). With --reference, PROBLEM-reference.csv
holds the reference GP's MAPE on every method's training sets at those HF counts (same columns).
Everything follows from --seed. The CSVs and JSON are rewritten as each repeat completes, and a
folder that already holds a run of the same configuration is resumed: its repeats are kept, only
the missing ones run, and the files hold the union.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
from pathlib import Path
from typing import Any

from ..support.arguments import integer
from ..support.errors import InputError
from ..support.outputs import output_folder

_LABELS = {
    "nmmf": "NMMF",
    "myopic": "myopic MF",
    "myopic-lf0": "myopic MF, LF only at HF points",
    "myopic-matched": "myopic MF, LF matched to NMMF",
    "nmmf-keep": "NMMF keeping its look-ahead LF",
    "nmmf-exact-lf": "NMMF, exact LF",
    "myopic-exact-lf": "myopic MF, exact LF",
    "hf-us": "HF-only US",
    "max-variance": "maximum variance (2.31)",
    "round-robin": "round robin (2.30)",
    "weighted": "weighted (2.32)",
}
# The thesis's statements about each figure, printed next to the measured crossovers.
THESIS_CLAIMS = {
    "park": "figure 2-5: NMMF most accurate after about 18 HF samples",
    "borehole": "figure 2-8: NMMF worst at first, most accurate after about 30-40 HF samples",
    "trebuchet": "figure 2-7: NMMF more accurate with fewer HF samples; benefit not substantial",
    "wing": "figure 2-9: NMMF lowest error as HF samples are added",
    "multi-output": "figure 2-10: maximum variance slightly best (except y1 below 20 samples)",
}


# ---------------------------------------------------------------------- outputs
def write_outputs(result: dict[str, Any], summary: dict[str, Any], out: Path, plot: bool = True) -> dict[str, Path]:
    """CSV of every MAPE, JSON summary and (plot) PNG figure in `out`; returns their paths."""
    from nearsub.common.analysis.albench import repeat_seed

    out.mkdir(parents=True, exist_ok=True)
    stem = out / result["problem"]
    paths = {
        "csv": stem.with_suffix(".csv"),
        "json": stem.with_suffix(".json"),
        "png": stem.with_suffix(".png"),
    }
    tables = [(paths["csv"], result["mape"], result["n_hf"])]
    if result.get("reference"):
        paths["reference"] = out / f"{result['problem']}-reference.csv"
        tables.append((paths["reference"], result["reference"]["mape"], result["reference"]["counts"]))
    for path, mapes, counts in tables:
        with _replacing(path) as fh:
            w = csv.writer(fh)
            w.writerow(["problem", "method", "repeat", "seed", "n_hf", "output", "mape_percent"])
            for m in result["methods"]:
                a = mapes[m]
                for r in range(a.shape[0]):
                    for i, n_hf in enumerate(counts):
                        for j, name in enumerate(result["outputs"]):
                            seed = repeat_seed(result["seed"], r)
                            w.writerow([result["problem"], m, r, seed, n_hf, name, repr(float(a[r, i, j]))])
    meta = {k: v for k, v in result.items() if k not in ("mape", "reference")}
    meta["reference_counts"] = result["reference"]["counts"] if result.get("reference") else []
    meta["thesis_claim"] = THESIS_CLAIMS.get(result["problem"], "")
    with _replacing(paths["json"]) as fh:
        json.dump({**meta, "summary": summary}, fh, indent=1)
    if plot:
        _plot(result, summary, paths["png"])
    return paths


@contextlib.contextmanager
def _replacing(path: Path):
    """A text file written beside `path` and moved over it when complete: a run stopped while
    writing leaves the previous file."""
    part = path.with_name(path.name + ".part")
    with open(part, "w", newline="") as fh:
        yield fh
    os.replace(part, path)


def _plot(result: dict[str, Any], summary: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    outputs = list(summary["outputs"])
    cols = min(2, len(outputs))
    rows = -(-len(outputs) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.6 * cols, 4.2 * rows), squeeze=False)
    counts = result["n_hf"]
    for ax, name in zip(axes.flat, outputs, strict=True):
        for m in result["methods"]:
            s = summary["outputs"][name]["stats"][m]
            (line,) = ax.plot(counts, s["median"], label=_LABELS.get(m, m))
            ax.fill_between(counts, s["q25"], s["q75"], color=line.get_color(), alpha=0.2)
        ax.set_yscale("log")
        ax.set_xlabel("number of HF samples")
        ax.set_ylabel("MAPE [%] (median, IQR band)")
        ax.set_title(name if len(outputs) > 1 else result["problem"])
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.suptitle(f"{result['problem']}: {result['repeats']} paired repeats, seed {result['seed']}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _print_report(result: dict[str, Any], summary: dict[str, Any], paths: dict[str, Path]) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=max(Console().width, 150))  # wide tables stay legible in logs
    counts, ref = result["n_hf"], summary["reference"]
    step = max(1, (counts[-1] - counts[0]) // 9)
    shown = [i for i, n in enumerate(counts) if (n - counts[0]) % step == 0 or n == counts[-1]]
    for name, out in summary["outputs"].items():
        table = Table(title=f"{result['problem']} / {name}: MAPE [%] median (mean ± 95 % CI)")
        table.add_column("HF")
        for m in result["methods"]:
            table.add_column(_LABELS.get(m, m))
        for b in out["win_rate"]:
            table.add_column(f"P({ref} < {b})")
        for i in shown:
            row = [str(counts[i])]
            for m in result["methods"]:
                s = out["stats"][m]
                row.append(f"{s['median'][i]:.3g} ({s['mean'][i]:.3g} ± {s['ci95_half_width'][i]:.2g})")
            row += [f"{out['win_rate'][b][i]:.2f}" for b in out["win_rate"]]
            table.add_row(*row)
        console.print(table)
        for b, n in out["crossover"].items():
            when = f"from {n} HF samples on" if n is not None else "not by the end"
            console.print(f"  {ref} median below {b}: {when}")
        if gp := out.get("reference_gp"):
            table = Table(title=f"{result['problem']} / {name}: the same training sets, reference GP: MAPE [%] median")
            table.add_column("HF")
            for m in result["methods"]:
                table.add_column(_LABELS.get(m, m))
            for i, n_hf in enumerate(gp["counts"]):
                table.add_row(str(n_hf), *(f"{gp['stats'][m]['median'][i]:.3g}" for m in result["methods"]))
            console.print(table)
    console.print(f"thesis: {THESIS_CLAIMS.get(result['problem'], '')}")
    console.print(f"wall time {result['wall_seconds']:.1f} s with {result['jobs']} job(s); files:")
    for p in paths.values():
        console.print(f"  {p}")


def read_outputs(problem: str, out: Path) -> dict[str, Any]:
    """The result `write_outputs` wrote to `out` (CSVs and JSON), to summarise and draw it again."""
    import numpy as np

    stem = out / problem
    try:
        meta = json.loads(stem.with_suffix(".json").read_text())
        tables = [_read_csv(stem.with_suffix(".csv"))]
        if meta.get("reference_counts"):
            tables.append(_read_csv(out / f"{problem}-reference.csv"))
    except FileNotFoundError as exc:
        raise LookupError(f"--from-files: no {exc.filename}") from None
    outputs, methods = meta["outputs"], meta["methods"]

    def arrays(rows, counts):
        a = {m: np.full((meta["repeats"], len(counts), len(outputs)), np.nan) for m in methods}
        for m, r, n_hf, name, value in rows:
            if r < meta["repeats"]:  # a CSV replaced after its JSON was not
                a[m][r, counts.index(n_hf), outputs.index(name)] = value
        return a

    result = {k: v for k, v in meta.items() if k not in ("summary", "reference_counts", "thesis_claim")}
    result["mape"] = arrays(tables[0], meta["n_hf"])
    result["reference"] = None
    if len(tables) > 1:
        result["reference"] = {"counts": meta["reference_counts"], "mape": arrays(tables[1], meta["reference_counts"])}
    return result


def _read_csv(path: Path) -> list[tuple[str, int, int, str, float]]:
    with open(path, newline="") as fh:
        return [
            (row["method"], int(row["repeat"]), int(row["n_hf"]), row["output"], float(row["mape_percent"]))
            for row in csv.DictReader(fh)
        ]


def markdown_tables(result: dict[str, Any], summary: dict[str, Any]) -> str:
    """Median MAPE (interquartile range) every 10 HF samples and at the reference counts, and the
    paired win rates of the fair pairs, as markdown tables (the docs' tables)."""
    ref_counts = result["reference"]["counts"] if result.get("reference") else []
    counts = result["n_hf"]
    shown = sorted({n for n in counts if n % 10 == 0} | set(ref_counts) | {counts[-1]})

    def g(v):
        return f"{v:.3g}"

    lines = []
    for name, out in summary["outputs"].items():
        methods = result["methods"]
        head = "| HF | " + " | ".join(_LABELS.get(m, m) for m in methods) + " |"
        lines += [f"{result['problem']} / {name}, {result['repeats']} repeats: median MAPE [%] (IQR)", "", head]
        lines.append("|---" * (len(methods) + 1) + "|")
        blocks = [("", out["stats"], counts, shown)]
        if gp := out.get("reference_gp"):
            blocks.append((", reference GP", gp["stats"], gp["counts"], gp["counts"]))
        for suffix, stats, at, rows in blocks:
            for n in rows:
                i = at.index(n)
                cells = [
                    f"{g(stats[m]['median'][i])} ({g(stats[m]['q25'][i])}-{g(stats[m]['q75'][i])})" for m in methods
                ]
                lines.append(f"| {n}{suffix} | " + " | ".join(cells) + " |")
        if out.get("pairs"):
            pairs = list(out["pairs"])
            lines += ["", "Paired win rates P(a < b):", ""]
            lines.append("| HF | " + " | ".join(p.replace("<", " < ") for p in pairs) + " |")
            lines.append("|---" * (len(pairs) + 1) + "|")
            for suffix, wins, at, rows in [("", out["pairs"], counts, shown)] + (
                [(", reference GP", gp["pairs"], gp["counts"], gp["counts"])] if gp else []
            ):
                for n in rows:
                    i = at.index(n)
                    lines.append(f"| {n}{suffix} | " + " | ".join(f"{wins[p][i]:.2f}" for p in pairs) + " |")
        lines.append("")
    return "\n".join(lines)


def al_bench_command(args) -> int:
    from nearsub.common.analysis.albench import check_request, summarise

    methods = tuple(args.methods.split(",")) if args.methods else None
    out = output_folder(args.out)
    if args.learn_rho:
        out = out / "learned-rho"
    if args.methods:
        out = out / args.methods.replace(",", "_")  # "fair" names its own folder
    if args.from_files:
        result = read_outputs(args.problem, out)
    else:
        # Bad input is reported in one line before the progress bar starts.
        _, _, n_hf0 = check_request(
            args.problem, args.hf_samples, args.n_lf0, args.n_hf0, methods, tuple(args.reference)
        )
        if args.hf_samples < n_hf0:  # the budget includes the initial HF design
            raise InputError(f"--hf-samples {args.hf_samples}: fewer than the initial HF design of {n_hf0} (--n-hf0)")
        # Repeats already in the folder are kept and only the missing ones run.
        previous = read_outputs(args.problem, out) if (out / f"{args.problem}.csv").exists() else None
        result = _run(args, methods, previous, out)
    summary = summarise(result)
    paths = write_outputs(result, summary, out)
    _print_report(result, summary, paths)
    if args.markdown:
        print(markdown_tables(result, summary))
    return 0


def _run(args, methods, previous, out) -> dict[str, Any]:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    from nearsub.common.analysis.albench import run_benchmark, summarise

    settings = {"n_lookahead": args.lookahead, "n_restarts": args.restarts, "n_polish": args.polish}
    if args.learn_rho:
        settings["rho"] = None
    columns = ("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns) as bar:
        job = bar.add_task(f"al-bench {args.problem}", total=None)
        return run_benchmark(
            args.problem,
            args.repeats,
            args.hf_samples,
            args.jobs,
            args.seed,
            n_lf0=args.n_lf0,
            n_hf0=args.n_hf0,
            methods=methods,
            test_points=args.test_points,
            reference_counts=tuple(args.reference),
            on_task_done=lambda done, total: bar.update(job, completed=done, total=total),
            time_limit=None if args.time_limit is None else 60.0 * args.time_limit,
            previous=previous,
            # The files are rewritten as each repeat completes: a stopped run resumes from them.
            on_checkpoint=lambda result: write_outputs(result, summarise(result), out, plot=False),
            **settings,
        )


def _minutes(text: str) -> float:
    import argparse

    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number of minutes")
    return value


def _counts(text: str) -> list[int]:
    import argparse

    try:
        return [int(n) for n in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--reference: {text!r} is not a comma list of HF counts") from None


def add_parser(subparsers) -> None:
    """Register `al-bench` on the `nearsub` command line."""
    p = subparsers.add_parser("al-bench")
    p.add_argument(
        "problem", help="benchmark of thesis sections 2.4-2.5: park, borehole, trebuchet, wing or multi-output"
    )
    p.add_argument("--repeats", type=integer(minimum=1), default=10, help="paired repeats (default 10)")
    p.add_argument("--hf-samples", type=integer(minimum=1), default=50, help="HF budget incl. the initial design")
    p.add_argument("--jobs", type=integer(minimum=1), default=1, help="worker processes")
    p.add_argument("--seed", type=int, default=0, help="base seed: designs, candidates, test set")
    p.add_argument("--n-lf0", type=integer(minimum=1), help="initial LF design size (default 4 (d + 1))")
    p.add_argument("--n-hf0", type=integer(minimum=1), help="initial HF design size (default d + 1)")
    p.add_argument("--lookahead", type=int, default=10, help="NMMF temporary LF points (thesis: 10)")
    p.add_argument("--restarts", type=int, default=2, help="optimiser starts per GP refit")
    p.add_argument("--polish", type=int, default=3, help="candidates polished by L-BFGS-B")
    p.add_argument("--test-points", type=int, default=2000, help="fixed test set size")
    p.add_argument(
        "--methods",
        help="comma list, reference first (default nmmf,myopic,hf-us; multi-output: "
        "max-variance,round-robin,weighted); variants: myopic-lf0, myopic-matched, nmmf-keep, "
        "nmmf-exact-lf, myopic-exact-lf; 'fair': all single-output methods and variants",
    )
    p.add_argument(
        "--reference",
        type=_counts,
        default=[],
        metavar="N,N,...",
        help="HF counts at which an independent MF GP (emukit on GPy; extra 'bench') refits every "
        "method's training sets",
    )
    p.add_argument("--learn-rho", action="store_true", help="ablation: learn rho instead of 1")
    p.add_argument(
        "--time-limit",
        type=_minutes,
        metavar="MIN",
        help="begin no repeat after MIN minutes (the repeats begun finish); write those",
    )
    p.add_argument(
        "--from-files",
        action="store_true",
        help="run nothing: summarise and draw again the CSVs a run wrote in the output folder",
    )
    p.add_argument("--markdown", action="store_true", help="also print the docs' markdown tables")
    p.add_argument(
        "-o",
        "--out",
        default="al-bench",
        help="output folder (default: al-bench); one holding a run of the same configuration is resumed",
    )
    p.set_defaults(func=al_bench_command)
