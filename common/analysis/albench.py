"""The thesis's active-learning comparisons (figures 2-5, 2-7 to 2-10): runner and statistics.

For a benchmark problem it runs NMMF, the myopic MF baseline and HF-only uncertainty sampling
side by side (`multi-output`: round robin, maximum variance and weighted selection, figure 2-10)
over paired repeats: repeat r gives every method the same seed, hence the same nested initial
design, and all repeats share one fixed test set. Repeats run in parallel processes (spawned,
one BLAS thread: multi-threaded BLAS on these small matrices is several times slower).
`summarise` gives the median, quartiles, mean +/- 95 % CI, the paired win rate of the reference
method over each baseline and the crossover HF counts. Everything follows from the seed.

Variants make the comparison fair in LF data (`VARIANTS`): a myopic baseline that keeps as many
LF runs per HF sample as NMMF runs (n + 1), NMMF keeping its look-ahead runs, and both methods
with the exact LF in the loop. With `reference_counts`, every method's training sets at those HF
counts are also refitted by an independent multi-fidelity GP (`reference_gp`, emukit on GPy).
"""

from __future__ import annotations

import multiprocessing
import time
from collections import Counter
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
# Extra methods by name: their CampaignSettings fields, given the run's other settings.
VARIANTS: dict[str, Callable[[dict[str, Any]], dict[str, Any]]] = {
    "myopic-lf0": lambda s: {"method": "myopic", "myopic_lf_picks": 0},
    # As many LF runs per HF sample as NMMF makes (n look-ahead + 1), all kept.
    "myopic-matched": lambda s: {
        "method": "myopic",
        "myopic_lf_picks": s.get("n_lookahead", CampaignSettings.n_lookahead),
    },
    "nmmf-keep": lambda s: {"method": "nmmf", "keep_lookahead": True},
    "nmmf-exact-lf": lambda s: {"method": "nmmf", "exact_lf": True},
    "myopic-exact-lf": lambda s: {"method": "myopic", "exact_lf": True},
}
# Every single-output method, the fair comparison (`--methods fair`); the reference first.
FAIR_METHODS = ("nmmf", "myopic", "myopic-matched", "nmmf-keep", "nmmf-exact-lf", "myopic-exact-lf", "hf-us")
# Algorithm 1 against its baseline, and the pairs that differ only in how the HF points are
# chosen (equal LF data kept, or the exact LF): their paired win rates are the fair comparison's
# verdicts. Every MF method is also paired with HF-only US.
FAIR_PAIRS = (("nmmf", "myopic"), ("nmmf-keep", "myopic-matched"), ("nmmf-exact-lf", "myopic-exact-lf"))


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
    reference_counts: tuple[int, ...] = ()


def method_settings(method: str, settings: dict[str, Any]) -> dict[str, Any]:
    """The CampaignSettings fields of a method name (a base method, a variant or a rule)."""
    if method in MULTI_OUTPUT_METHODS:
        return {"method": "hf-us", "selection": method}
    return VARIANTS[method](settings) if method in VARIANTS else {"method": method}


def _run_task(
    task: _Task,
) -> tuple[str, int, list[tuple[int, np.ndarray]], list[tuple[int, np.ndarray]], float, float]:
    """One campaign of one method and repeat; returns the test MAPE at every HF count, the
    reference model's at `reference_counts`, and its wall and CPU seconds (this process)."""
    start, cpu_start = time.perf_counter(), time.process_time()
    problem = get_problem(task.problem)
    settings = CampaignSettings(seed=task.seed, **method_settings(task.method, task.settings), **task.settings)
    rows: list[tuple[int, np.ndarray]] = []
    reference_rows: list[tuple[int, np.ndarray]] = []

    def record(campaign):
        rows.append((campaign.n_hf, mape(campaign.predict(task.X_test), task.Y_test)))
        if campaign.n_hf in task.reference_counts:
            from nearsub.common.learning.reference_gp import predict_hf

            Y = predict_hf(
                problem.bounds,
                *campaign.data("hf"),
                task.X_test,
                lf_data=campaign.data("lf") if settings.lf_runs else None,
                lf=problem.lf if settings.exact_lf else None,
                restarts=settings.n_restarts,
                seed=task.seed,
            )
            reference_rows.append((campaign.n_hf, mape(Y, task.Y_test)))

    run_campaign(Campaign(problem, settings), problem, record)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    return task.method, task.repeat, rows, reference_rows, wall, cpu


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
    reference_counts: tuple[int, ...] = (),
    on_task_done: Callable[[int, int], None] | None = None,
    time_limit: float | None = None,
    previous: dict[str, Any] | None = None,
    on_checkpoint: Callable[[dict[str, Any]], None] | None = None,
    **settings: Any,
) -> dict[str, Any]:
    """Run the paired comparison and return raw results: per method, an array (repeats, n_hf
    counts, outputs) of MAPE [%], the HF counts, and the run's configuration and wall time.

    reference_counts: HF counts at which the reference GP (`reference_gp`) refits each
    campaign's data; its MAPE is under "reference" (arrays (repeats, counts, outputs)).
    settings: further `CampaignSettings` fields (n_lookahead, n_restarts, n_polish, rho, ...).
    on_task_done(done, total) is called as each campaign finishes.
    time_limit: seconds after which no further repeat starts (the repeats begun finish); the
    result then holds fewer repeats ("repeats") than asked ("repeats_requested"). Each repeat's
    numbers depend only on its seed, so they are the same as in a run without the limit.
    previous: an earlier result of the same configuration (LookupError naming the field that
    differs); only its missing repeats run, and the result is the union, equal to one run of
    them all.
    on_checkpoint(result) is called whenever the repeats finished so far (from the first) grow:
    the result so far, so a run that is stopped can be resumed from what it wrote.
    """
    problem = get_problem(problem_name)
    methods, n_lf0, n_hf0 = check_request(problem_name, hf_samples, n_lf0, n_hf0, methods, reference_counts)
    config = dict(settings, hf_budget=hf_samples, n_lf0=n_lf0, n_hf0=n_hf0)
    counts = list(range(n_hf0, hf_samples + 1))
    ref_counts = sorted(reference_counts)
    done = 0
    if previous is not None:
        request = {
            "problem": problem_name,
            "methods": list(methods),
            "seed": seed,
            "hf_samples": hf_samples,
            "test_points": test_points,
            "reference counts": ref_counts,
            "settings": config,
        }
        if conflict := resume_conflict(previous, request):
            raise LookupError(conflict)
        done = previous["repeats"]
    if done >= repeats:
        return _union(previous, None, repeats, 0.0)
    single_blas_thread()  # inherited by the spawned workers
    start = time.perf_counter()
    deadline = None if time_limit is None else start + time_limit

    def assemble(results, upto):
        """The result of repeats done..upto - 1 (all in `results`), joined to `previous`."""

        def empty(n):
            return {method: np.full((upto, n, problem.n_outputs), np.nan) for method in methods}

        mape_by_method, reference = empty(len(counts)), empty(len(ref_counts))
        task_seconds = {method: 0.0 for method in methods}
        task_cpu = {method: 0.0 for method in methods}
        for method, r, rows, reference_rows, seconds, cpu in results:
            task_seconds[method] += seconds
            task_cpu[method] += cpu
            for n_hf, err in rows:
                mape_by_method[method][r, counts.index(n_hf)] = err
            for n_hf, err in reference_rows:
                reference[method][r, ref_counts.index(n_hf)] = err
        wall = time.perf_counter() - start
        run = {"repeats": [done, upto], "jobs": jobs, "wall_seconds": wall, "time_limit_seconds": time_limit}
        result = {
            "problem": problem_name,
            "outputs": list(problem.output_names),
            "methods": list(methods),
            "repeats": upto,
            "repeats_requested": repeats,
            "time_limit_seconds": time_limit,
            "hf_samples": hf_samples,
            "seed": seed,
            "jobs": jobs,
            "settings": config,
            "test_points": test_points,
            "n_hf": counts,
            "mape": mape_by_method,
            "reference": {"counts": ref_counts, "mape": reference} if ref_counts else None,
            "wall_seconds": wall,
            "task_seconds_per_method": task_seconds,  # wall, summed over repeats
            "task_cpu_seconds_per_method": task_cpu,  # CPU of the worker processes, summed over repeats
            "runs": [run],
        }
        return result if previous is None else _union(previous, result, repeats, wall)

    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=max(1, jobs), mp_context=ctx) as pool:
        X_test, Y_test = _test_set(problem, test_points, seed, pool, max(1, jobs))
        tasks = [
            _Task(problem_name, method, r, repeat_seed(seed, r), config, X_test, Y_test, tuple(reference_counts))
            for r in range(done, repeats)
            for method in methods
        ]
        last = [done]

        def checkpoint(results):  # the union up to the first repeat not yet whole
            finished = Counter(r for _, r, *_ in results)
            upto = last[0]
            while finished[upto] == len(methods):
                upto += 1
            if on_checkpoint is not None and upto > last[0]:
                last[0] = upto
                on_checkpoint(assemble([x for x in results if x[1] < upto], upto))

        results = _run_all(pool, tasks, on_task_done, deadline, checkpoint)
    return assemble(results, 1 + max(r for _, r, *_ in results))  # begun repeats are a prefix


def resume_conflict(previous: dict[str, Any], request: dict[str, Any]) -> str | None:
    """Why an earlier result cannot be resumed by `request` (the first field that differs), or
    None. Values are compared as the JSON files hold them."""
    import json

    def norm(value):
        return json.loads(json.dumps(value))

    ref = previous.get("reference")
    old = {
        **{k: previous.get(k) for k in ("problem", "methods", "seed", "hf_samples", "test_points")},
        "reference counts": ref["counts"] if ref else [],
    }
    old_settings, new_settings = norm(previous.get("settings", {})), norm(request["settings"])
    fields = [(k, norm(old[k]), norm(request[k])) for k in old]
    fields += [(f"settings.{k}", old_settings.get(k), new_settings.get(k)) for k in sorted(old_settings | new_settings)]
    for name, was, now in fields:
        if was != now:
            return f"cannot resume: the earlier run's {name} is {was!r}, this run's {now!r}"
    return None


def _union(previous: dict[str, Any], new: dict[str, Any] | None, requested: int, wall: float) -> dict[str, Any]:
    """`previous` with the repeats of `new` (which follow its own) appended; times summed."""
    done = previous["repeats"]
    runs = previous.get("runs") or [{"repeats": [0, done], "wall_seconds": previous.get("wall_seconds")}]
    if new is None:
        return {**previous, "repeats_requested": requested, "runs": runs}

    def join(old, fresh):
        return {m: np.concatenate([old[m][:done], fresh[m][done:]]) for m in new["methods"]}

    result = {**new, "mape": join(previous["mape"], new["mape"])}
    if new["reference"]:
        result["reference"] = {
            **new["reference"],
            "mape": join(previous["reference"]["mape"], new["reference"]["mape"]),
        }
    for key in ("task_seconds_per_method", "task_cpu_seconds_per_method"):
        old = previous.get(key) or {}
        result[key] = {m: old.get(m, 0.0) + t for m, t in new[key].items()}
    result["wall_seconds"] = (previous.get("wall_seconds") or 0.0) + wall
    result["runs"] = runs + new["runs"]
    return result


def check_request(
    problem_name: str,
    hf_samples: int,
    n_lf0: int | None = None,
    n_hf0: int | None = None,
    methods: tuple[str, ...] | None = None,
    reference_counts: tuple[int, ...] = (),
) -> tuple[tuple[str, ...], int, int]:
    """The methods ("fair" expanded) and initial design sizes of a request; LookupError naming
    an unknown problem or method, a reference count outside the run, or a missing extra."""
    problem = get_problem(problem_name)
    multi = problem.lf is None
    methods = methods or (MULTI_OUTPUT_METHODS if multi else SINGLE_OUTPUT_METHODS)
    known = MULTI_OUTPUT_METHODS if multi else SINGLE_OUTPUT_METHODS + tuple(VARIANTS)
    if methods == ("fair",):
        methods = FAIR_METHODS
    if unknown := set(methods) - set(known):
        raise LookupError(f"unknown method(s) {sorted(unknown)} for {problem_name}; use {known}")
    lf0, hf0 = default_design(problem.d)
    n_lf0, n_hf0 = n_lf0 or lf0, n_hf0 or hf0
    if bad := [n for n in reference_counts if not n_hf0 <= n <= hf_samples]:
        raise LookupError(f"--reference: count(s) {bad} outside the HF counts {n_hf0}..{hf_samples}")
    if reference_counts:
        from nearsub.common.learning.reference_gp import missing

        if reason := missing():
            raise LookupError(f"--reference: the reference GP cannot run: {reason}")
    return tuple(methods), max(n_lf0, n_hf0), n_hf0


def _run_all(pool, tasks, on_task_done, deadline=None, on_result=None):
    """Results of the tasks (submitted repeat by repeat). After `deadline` (perf_counter) the
    tasks of repeats that have not begun are cancelled, so every repeat run is whole; checked as
    each task finishes, which is when a worker takes the next."""
    futures = [pool.submit(_run_task, task) for task in tasks]
    results = []
    for future in as_completed(futures):
        if future.cancelled():
            continue
        results.append(future.result())
        if on_result is not None:
            on_result(results)
        if on_task_done is not None:
            on_task_done(len(results), len(tasks))
        if deadline is not None and time.perf_counter() > deadline:
            begun = {t.repeat for f, t in zip(futures, tasks, strict=True) if f.running() or f.done()}
            for f, t in zip(futures, tasks, strict=True):
                if t.repeat not in begun:
                    f.cancel()
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
    """Median, quartiles, mean +/- 95 % CI, paired win rates and crossovers per output.

    "pairs" holds the paired win rates P(a < b) of the fair pairs (`FAIR_PAIRS`, and each MF
    method against HF-only US) whose methods were both run, keyed "a<b"."""
    from scipy import stats

    methods, counts = result["methods"], result["n_hf"]
    reference, baselines = methods[0], methods[1:]
    outputs = list(result["outputs"])
    with_mean = len(outputs) > 1  # figure 2-10 also averages the outputs
    if with_mean:
        outputs.append("mean")

    def per_output(arrays):
        if not with_mean:
            return arrays
        return {m: np.concatenate([a, a.mean(axis=2, keepdims=True)], axis=2) for m, a in arrays.items()}

    mapes = per_output(result["mape"])
    ref_gp = result.get("reference")
    ref_mapes = per_output(ref_gp["mape"]) if ref_gp else None
    pairs = [p for p in FAIR_PAIRS if set(p) <= set(methods)]
    if "hf-us" in methods:
        pairs += [(m, "hf-us") for m in methods if m != "hf-us"]
    summary: dict[str, Any] = {"reference": reference, "outputs": {}}
    for j, name in enumerate(outputs):
        per_method = {m: _stats(mapes[m][:, :, j], stats) for m in methods}
        ref = mapes[reference][:, :, j]
        win = {b: np.mean(ref < mapes[b][:, :, j], axis=0).tolist() for b in baselines}
        cross = {b: crossover(counts, per_method[reference]["median"], per_method[b]["median"]) for b in baselines}
        pair_win = {f"{a}<{b}": np.mean(mapes[a][:, :, j] < mapes[b][:, :, j], axis=0).tolist() for a, b in pairs}
        summary["outputs"][name] = {"stats": per_method, "win_rate": win, "crossover": cross, "pairs": pair_win}
        if ref_mapes:  # the same training sets, refitted by the reference GP
            a = {m: ref_mapes[m][:, :, j] for m in methods}
            summary["outputs"][name]["reference_gp"] = {
                "counts": ref_gp["counts"],
                "stats": {m: _stats(a[m], stats) for m in methods},
                "win_rate": {b: np.mean(a[reference] < a[b], axis=0).tolist() for b in baselines},
                "pairs": {f"{x}<{y}": np.mean(a[x] < a[y], axis=0).tolist() for x, y in pairs},
            }
    return summary


def _stats(a: np.ndarray, stats) -> dict[str, list[float]]:
    """Median, quartiles, mean and the 95 % CI half width (t) over repeats (axis 0)."""
    n = a.shape[0]
    half = stats.t.ppf(0.975, n - 1) * a.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else 0 * a[0]
    return {
        "median": np.median(a, axis=0).tolist(),
        "q25": np.percentile(a, 25, axis=0).tolist(),
        "q75": np.percentile(a, 75, axis=0).tolist(),
        "mean": a.mean(axis=0).tolist(),
        "ci95_half_width": np.asarray(half).tolist(),
    }
