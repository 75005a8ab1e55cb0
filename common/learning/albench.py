"""The thesis's active-learning comparisons (figures 2-5, 2-7 to 2-10): runner and statistics.

For a benchmark problem it runs NMMF, the myopic MF baseline and HF-only uncertainty sampling
side by side (`multi-output`: round robin, maximum variance and weighted selection, figure 2-10)
over paired repeats: repeat r gives every method the same seed, hence the same nested initial
design, and all repeats share one fixed test set. Repeats run in parallel processes (spawned,
one BLAS thread: multi-threaded BLAS on these small matrices is several times slower).
`summarise` gives the median, quartiles, mean +/- 95 % CI, the paired win rate of the reference
method over each baseline and the crossover HF counts. Everything follows from the seed.
"""

from __future__ import annotations

import multiprocessing
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any

import numpy as np

from nearsub.common.learning.active import Campaign, CampaignSettings, run_campaign
from nearsub.common.learning.testproblems import get_problem
from nearsub.common.runtime.processes import single_blas_thread

SINGLE_OUTPUT_METHODS = ("nmmf", "myopic", "hf-us")
MULTI_OUTPUT_METHODS = ("max-variance", "round-robin", "weighted")  # reference first
# Extra baselines by name: CampaignSettings fields.
VARIANTS = {"myopic-lf0": {"method": "myopic", "myopic_lf_picks": 0}}


def mape(Y_pred: np.ndarray, Y_true: np.ndarray) -> np.ndarray:
    """Mean absolute percentage error per output, (2.18) times 100."""
    return 100.0 * np.mean(np.abs((Y_pred - Y_true) / Y_true), axis=0)


def repeat_seed(seed: int, repeat: int) -> int:
    """The seed of every method's campaign in `repeat`: paired repeats share it."""
    return seed * 10_000 + repeat


def default_design(d: int) -> tuple[int, int]:
    """(n_lf0, n_hf0) when not given: d + 1 HF points nested in 4 (d + 1) LF points.

    The thesis does not print its initial designs; this gives Park (d = 4) 20 LF and 5 HF points.
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
    on_task_done: Callable[[int, int], None] | None = None,
    **settings: Any,
) -> dict[str, Any]:
    """Run the paired comparison and return raw results: per method, an array (repeats, n_hf
    counts, outputs) of MAPE [%], the HF counts, and the run's configuration and wall time.

    settings: further `CampaignSettings` fields (n_lookahead, n_restarts, n_polish, rho, ...).
    on_task_done(done, total) is called as each campaign finishes.
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
    single_blas_thread()  # inherited by the spawned workers
    start = time.perf_counter()
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=max(1, jobs), mp_context=ctx) as pool:
        X_test, Y_test = _test_set(problem, test_points, seed, pool, max(1, jobs))
        tasks = [
            _Task(problem_name, method, r, repeat_seed(seed, r), config, X_test, Y_test)
            for r in range(repeats)
            for method in methods
        ]
        results = _run_all(pool, tasks, on_task_done)
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


def _run_all(pool, tasks, on_task_done):
    futures = [pool.submit(_run_task, task) for task in tasks]
    results = []
    for future in as_completed(futures):
        results.append(future.result())
        if on_task_done is not None:
            on_task_done(len(results), len(tasks))
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
