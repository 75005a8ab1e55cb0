"""`nearsub al-bench`: the thesis's active-learning comparisons (figures 2-5, 2-7 to 2-10).

For a benchmark problem it runs NMMF, the myopic MF baseline and HF-only uncertainty sampling
side by side (`multi-output`: round robin, maximum variance and weighted selection, figure 2-10)
over paired repeats: repeat r gives every method the same seed, hence the same nested initial
design, and all repeats share one fixed test set. Repeats run in parallel processes (spawned,
single-threaded BLAS: multi-threaded BLAS on these small matrices is several times slower).

Outputs in --out: PROBLEM.csv (MAPE (2.18) in percent per method, repeat, HF count and output),
PROBLEM.png (median and interquartile band against the number of HF samples), PROBLEM.json
(median, quartiles, mean +/- 95 % CI, the paired win rate of the reference method over each
baseline, the crossover HF counts and the wall time). Everything follows from --seed.
"""

from __future__ import annotations

import csv
import json
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nearsub.common.learning.active import Campaign, CampaignSettings, run_campaign
from nearsub.common.learning.testproblems import PROBLEMS, get_problem

__all__ = ["add_parser", "albench_command", "run_benchmark", "summarise", "crossover", "mape"]

SINGLE_OUTPUT_METHODS = ("nmmf", "myopic", "hf-us")
MULTI_OUTPUT_METHODS = ("max-variance", "round-robin", "weighted")  # reference first
# Extra baselines by name: CampaignSettings fields.
VARIANTS = {"myopic-lf0": {"method": "myopic", "myopic_lf_picks": 0}}
_LABELS = {
    "nmmf": "NMMF",
    "myopic": "myopic MF",
    "myopic-lf0": "myopic MF, LF only at HF points",
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
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def mape(Y_pred: np.ndarray, Y_true: np.ndarray) -> np.ndarray:
    """Mean absolute percentage error per output, (2.18) times 100."""
    return 100.0 * np.mean(np.abs((Y_pred - Y_true) / Y_true), axis=0)


def default_design(d: int) -> tuple[int, int]:
    """(n_lf0, n_hf0) when not given: d + 1 HF points nested in 4 (d + 1) LF points.

    The thesis does not print its initial designs; Park gets (20, 5) as in the notes' pilot.
    """
    return 4 * (d + 1), d + 1


@dataclass(frozen=True)
class _Task:
    problem: str
    method: str
    repeat: int
    seed: int
    settings: dict[str, Any]
    X_test: np.ndarray
    Y_test: np.ndarray


def _run_task(task: _Task) -> tuple[str, int, list[tuple[int, np.ndarray]], float]:
    """One campaign of one method and repeat; returns the test MAPE at every HF count."""
    start = time.perf_counter()
    problem = get_problem(task.problem)
    if task.method in MULTI_OUTPUT_METHODS:
        spec = {"method": "hf-us", "selection": task.method}
    else:
        spec = VARIANTS.get(task.method, {"method": task.method})
    settings = CampaignSettings(seed=task.seed, **spec, **task.settings)
    rows: list[tuple[int, np.ndarray]] = []

    def record(campaign):
        rows.append((campaign.n_hf, mape(campaign.predict(task.X_test), task.Y_test)))

    run_campaign(Campaign(problem, settings), problem, record)
    return task.method, task.repeat, rows, time.perf_counter() - start


def _evaluate_hf(problem_name: str, X: np.ndarray) -> np.ndarray:
    return get_problem(problem_name).hf(X)


def _test_set(problem, n: int, seed: int, pool, jobs: int) -> tuple[np.ndarray, np.ndarray]:
    """A fixed, feasible, uniform random test set and its HF values (evaluated on the pool)."""
    rng = np.random.default_rng([seed, 7])
    lower, upper = problem.bounds[:, 0], problem.bounds[:, 1]
    X = np.empty((0, problem.d))
    while len(X) < n:
        draw = lower + rng.uniform(size=(n, problem.d)) * (upper - lower)
        X = np.vstack([X, draw[problem.feasible(draw)]])
    X = X[:n]
    chunks = np.array_split(X, max(1, min(len(X), 8 * jobs)))
    Y = np.vstack(list(pool.map(_evaluate_hf, [problem.name] * len(chunks), chunks)))
    return X, Y


def run_benchmark(
    problem_name: str,
    repeats: int,
    hf_samples: int,
    jobs: int = 1,
    seed: int = 0,
    *,
    n_lf0: int | None = None,
    n_hf0: int | None = None,
    methods: tuple[str, ...] | None = None,
    test_points: int = 2000,
    progress: bool = True,
    **settings: Any,
) -> dict[str, Any]:
    """Run the paired comparison and return raw results: per method, an array (repeats, n_hf
    counts, outputs) of MAPE [%], the HF counts, and the run's configuration and wall time.

    settings: further `CampaignSettings` fields (n_lookahead, n_restarts, n_polish, rho, ...).
    """
    problem = get_problem(problem_name)
    multi = problem.lf is None
    methods = methods or (MULTI_OUTPUT_METHODS if multi else SINGLE_OUTPUT_METHODS)
    known = MULTI_OUTPUT_METHODS if multi else SINGLE_OUTPUT_METHODS + tuple(VARIANTS)
    if unknown := set(methods) - set(known):
        raise LookupError(f"unknown method(s) {sorted(unknown)} for {problem_name}; use {known}")
    lf0, hf0 = default_design(problem.d)
    n_lf0, n_hf0 = n_lf0 or lf0, n_hf0 or hf0
    config = dict(settings, hf_budget=hf_samples, n_lf0=max(n_lf0, n_hf0), n_hf0=n_hf0)
    for var in _THREAD_VARS:  # inherited by the spawned workers
        os.environ[var] = "1"
    start = time.perf_counter()
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=max(1, jobs), mp_context=ctx) as pool:
        X_test, Y_test = _test_set(problem, test_points, seed, pool, max(1, jobs))
        tasks = [
            _Task(problem_name, method, r, seed * 10_000 + r, config, X_test, Y_test)
            for r in range(repeats)
            for method in methods
        ]
        results = _run_all(pool, tasks, progress, f"al-bench {problem_name}")
    counts = list(range(n_hf0, hf_samples + 1))
    mape_by_method = {method: np.full((repeats, len(counts), problem.n_outputs), np.nan) for method in methods}
    task_seconds = {method: 0.0 for method in methods}
    for method, r, rows, seconds in results:
        task_seconds[method] += seconds
        for n_hf, err in rows:
            mape_by_method[method][r, counts.index(n_hf)] = err
    return {
        "problem": problem_name,
        "outputs": list(problem.output_names),
        "methods": list(methods),
        "repeats": repeats,
        "hf_samples": hf_samples,
        "seed": seed,
        "jobs": jobs,
        "settings": config,
        "test_points": test_points,
        "n_hf": counts,
        "mape": mape_by_method,
        "wall_seconds": time.perf_counter() - start,
        "task_seconds_per_method": task_seconds,
    }


def _run_all(pool, tasks, progress: bool, title: str):
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    columns = (
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
    )
    results = []
    with Progress(*columns, disable=not progress) as bar:
        job = bar.add_task(title, total=len(tasks))
        futures = [pool.submit(_run_task, task) for task in tasks]
        for future in as_completed(futures):
            results.append(future.result())
            bar.advance(job)
    return results


# ---------------------------------------------------------------------- statistics
def crossover(counts: list[int], ref: np.ndarray, other: np.ndarray) -> int | None:
    """First HF count from which the reference median stays below the other's; None if never."""
    below = np.asarray(ref) < np.asarray(other)
    if not below[-1]:
        return None
    first = len(below)
    while first > 0 and below[first - 1]:
        first -= 1
    return counts[first]


def summarise(result: dict[str, Any]) -> dict[str, Any]:
    """Median, quartiles, mean +/- 95 % CI, paired win rates and crossovers per output."""
    from scipy import stats

    methods, counts = result["methods"], result["n_hf"]
    reference, baselines = methods[0], methods[1:]
    outputs = list(result["outputs"])
    mapes = {m: result["mape"][m] for m in methods}
    if len(outputs) > 1:  # figure 2-10 also averages the outputs
        outputs.append("mean")
        mapes = {m: np.concatenate([a, a.mean(axis=2, keepdims=True)], axis=2) for m, a in mapes.items()}
    summary: dict[str, Any] = {"reference": reference, "outputs": {}}
    for j, name in enumerate(outputs):
        per_method = {}
        for m in methods:
            a = mapes[m][:, :, j]
            n = a.shape[0]
            half = stats.t.ppf(0.975, n - 1) * a.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else 0 * a[0]
            per_method[m] = {
                "median": np.median(a, axis=0).tolist(),
                "q25": np.percentile(a, 25, axis=0).tolist(),
                "q75": np.percentile(a, 75, axis=0).tolist(),
                "mean": a.mean(axis=0).tolist(),
                "ci95_half_width": np.asarray(half).tolist(),
            }
        ref = mapes[reference][:, :, j]
        win = {b: np.mean(ref < mapes[b][:, :, j], axis=0).tolist() for b in baselines}
        cross = {b: crossover(counts, per_method[reference]["median"], per_method[b]["median"]) for b in baselines}
        summary["outputs"][name] = {"stats": per_method, "win_rate": win, "crossover": cross}
    return summary


# ---------------------------------------------------------------------- outputs
def write_outputs(result: dict[str, Any], summary: dict[str, Any], out: Path) -> dict[str, Path]:
    """CSV of every MAPE, JSON summary and PNG figure in `out`; returns their paths."""
    out.mkdir(parents=True, exist_ok=True)
    stem = out / result["problem"]
    paths = {
        "csv": stem.with_suffix(".csv"),
        "json": stem.with_suffix(".json"),
        "png": stem.with_suffix(".png"),
    }
    with open(paths["csv"], "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["problem", "method", "repeat", "seed", "n_hf", "output", "mape_percent"])
        for m in result["methods"]:
            a = result["mape"][m]
            for r in range(a.shape[0]):
                for i, n_hf in enumerate(result["n_hf"]):
                    for j, name in enumerate(result["outputs"]):
                        w.writerow(
                            [
                                result["problem"],
                                m,
                                r,
                                result["seed"] * 10_000 + r,
                                n_hf,
                                name,
                                repr(float(a[r, i, j])),
                            ]
                        )
    meta = {k: v for k, v in result.items() if k != "mape"}
    meta["thesis_claim"] = THESIS_CLAIMS.get(result["problem"], "")
    with open(paths["json"], "w") as fh:
        json.dump({**meta, "summary": summary}, fh, indent=1)
    _plot(result, summary, paths["png"])
    return paths


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
    console.print(f"thesis: {THESIS_CLAIMS.get(result['problem'], '')}")
    console.print(f"wall time {result['wall_seconds']:.1f} s with {result['jobs']} job(s); files:")
    for p in paths.values():
        console.print(f"  {p}")


def albench_command(args) -> int:
    settings = {"n_lookahead": args.lookahead, "n_restarts": args.restarts, "n_polish": args.polish}
    if args.learn_rho:
        settings["rho"] = None
    result = run_benchmark(
        args.problem,
        args.repeats,
        args.hf_samples,
        args.jobs,
        args.seed,
        n_lf0=args.n_lf0,
        n_hf0=args.n_hf0,
        methods=tuple(args.methods.split(",")) if args.methods else None,
        test_points=args.test_points,
        **settings,
    )
    summary = summarise(result)
    out = Path(args.out)
    if args.learn_rho:
        out = out / "learned-rho"
    if args.methods:
        out = out / args.methods.replace(",", "_")
    paths = write_outputs(result, summary, out)
    _print_report(result, summary, paths)
    return 0


def add_parser(subparsers) -> None:
    """Register `al-bench` on the `nearsub` command line."""
    p = subparsers.add_parser("al-bench", help="NMMF vs myopic MF vs HF-only active learning on thesis benchmarks")
    p.add_argument("problem", choices=sorted(PROBLEMS), help="benchmark (multi-output: figure 2-10)")
    p.add_argument("--repeats", type=int, default=10, help="paired repeats (default 10)")
    p.add_argument("--hf-samples", type=int, default=50, help="HF budget incl. the initial design")
    p.add_argument("--jobs", type=int, default=1, help="worker processes")
    p.add_argument("--seed", type=int, default=0, help="base seed: designs, candidates, test set")
    p.add_argument("--n-lf0", type=int, help="initial LF design size (default 4 (d + 1))")
    p.add_argument("--n-hf0", type=int, help="initial HF design size (default d + 1)")
    p.add_argument("--lookahead", type=int, default=10, help="NMMF temporary LF points (thesis: 10)")
    p.add_argument("--restarts", type=int, default=2, help="optimiser starts per GP refit")
    p.add_argument("--polish", type=int, default=3, help="candidates polished by L-BFGS-B")
    p.add_argument("--test-points", type=int, default=2000, help="fixed test set size")
    p.add_argument(
        "--methods",
        help="comma list, reference first (default nmmf,myopic,hf-us; multi-output: "
        "max-variance,round-robin,weighted); extra baseline: myopic-lf0",
    )
    p.add_argument("--learn-rho", action="store_true", help="ablation: learn rho instead of 1")
    p.add_argument("--out", default="al-bench", help="output folder (default: al-bench)")
    p.set_defaults(func=albench_command)
