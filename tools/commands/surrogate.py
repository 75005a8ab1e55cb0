"""`nearsub surrogate info|predict|validate` (inspect, query and validate a surrogate model file) and
`nearsub bench surrogate` (prediction, query and fit timings against their targets).

Without a MODEL argument both commands use the shipped model, or, until one ships, the analytic
test fixture (with a warning on stderr; common/surrogate.py).
"""

from __future__ import annotations

import csv
import functools
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from nearsub.apps.services import RemoteSurrogate
from nearsub.common.learning.gp import GaussianProcess, MultiOutputGP
from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Bus, app_endpoints, app_runtime, free_tcp_port
from nearsub.common.runtime.processes import single_blas_thread, spawn_app, stop
from nearsub.common.surrogate import calibration
from nearsub.common.surrogate.domain import BOUNDS, CONSTRAINT_NAMES, INPUT_NAMES, constraint_values, sample_feasible
from nearsub.common.surrogate.model import (
    Surrogate,
    analytic_coefficients,
    decode_reply,
    default_model_path,
    encode_query,
    load_surrogate,
    surrogate_key,
)
from nearsub.common.surrogate.modelfile import ModelFileError, lf_hash, lf_identity, load_model, save_model
from nearsub.common.surrogate.validation import (
    HELD_OUT_SEED,
    THESIS_TEST_POINTS,
    PointsFileError,
    evaluate_rows,
    latin_hypercube_feasible,
    read_points_file,
    validation_summary,
)

from ..support.arguments import integer
from ..support.outputs import output_file, output_folder

# Targets (docs/design.md, "Performance targets"): in-process point and batch, query round trip, fit.
TARGETS = {
    "lf_in_loop_point_us": 1000.0,
    "point_us": 50.0,
    "batch_ms": 50.0,
    "query_median_us": 500.0,
    "query_p99_us": 2000.0,
    "fit_s": 1.0,
}


def child_env() -> dict[str, str]:
    """This environment with single-threaded BLAS, for the child processes we start."""
    return single_blas_thread(dict(os.environ))


def write_analytic_model(path: str | os.PathLike, n: int = 100, seed: int = 0) -> Path:
    """Write the analytic test fixture to `path`, fitted in a child process with one BLAS thread."""
    code = (
        "import sys; from nearsub.common.surrogate.model import analytic_model; "
        "analytic_model(int(sys.argv[2]), int(sys.argv[3]), sys.argv[1])"
    )
    subprocess.run([sys.executable, "-c", code, str(path), str(n), str(seed)], env=child_env(), check=True)
    return Path(path)


@contextmanager
def local_server(model_path: str | os.PathLike, community: str, timeout: float = 30.0) -> Iterator[tuple[Bus, str]]:
    """A router on a free loopback port and a surrogate server (separate processes); yields a bus
    linked as a mission app's (`bus.app_endpoints`) that already sees the server's liveliness
    token, and the router's endpoint. Both processes are stopped on exit."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    started: list[subprocess.Popen] = []
    with tempfile.TemporaryFile() as output:
        try:
            started.append(spawn_app("router", ["--listen", endpoint, "--with-parent"], output))
            # The server and the bench's bus run as a mission's apps do (Zenoh's threads,
            # `bus.app_runtime`; the bus a peer on this host's router, as the sim is), so the
            # round trip is the one a mission's sim sees.
            with app_runtime():
                server = ["--model", str(model_path), "--community", community, "--connect", endpoint]
                started.append(spawn_app("surrogate", server, output))
                with Bus(app_endpoints((endpoint,))) as bus:
                    token = keys.alive(community, "surrogate", "*")
                    end = time.monotonic() + timeout
                    while not bus.alive(token, timeout=0.5):
                        if time.monotonic() > end or any(p.poll() is not None for p in started):
                            output.seek(0)
                            text = output.read().decode(errors="replace")
                            raise RuntimeError(f"surrogate server did not come up on {endpoint}:\n{text}")
                        time.sleep(0.05)
                    yield bus, endpoint
        finally:
            stop(started)


# ---------------------------------------------------------------------------------- info
def describe(surrogate: Surrogate) -> dict:
    """What `info` shows: the model's identity and kind, domain, warping, LF identity, training
    size, hyperparameters with each output's log marginal likelihood, provenance."""
    loaded = surrogate.loaded
    model = surrogate.model
    gps = model.gps
    in_loop = surrogate.kind == "lf_in_loop"
    warps = model.warping.names if in_loop else ("identity",) * len(loaded.input_names)
    return {
        "model": surrogate.source,
        "model_id": surrogate.model_id,
        "kind": surrogate.kind,
        "format_version": loaded.format_version,
        "saved_utc": loaded.saved_utc,
        "training_points": int(gps[0].X_train_.shape[0]),
        "low_fidelity": (
            {**lf_identity(), "hash": lf_hash(lf_identity()), "evaluated": "exactly, at every prediction"}
            if in_loop
            else None
        ),
        "inputs": [
            {
                "name": name,
                "unit": loaded.units.get(name, ""),
                "bounds": [float(low), float(high)],
                "warping": warp,
                # in the warped coordinate for a warped input
                "length_scales": {
                    out: float(gp.length_scales[k]) for out, gp in zip(loaded.output_names, gps, strict=True)
                },
            }
            for k, (name, (low, high), warp) in enumerate(zip(loaded.input_names, loaded.bounds, warps, strict=True))
        ],
        "outputs": [
            {
                "name": name,
                "unit": loaded.units.get(name, ""),
                "signal_std": math.sqrt(gp.signal_variance) * gp.y_std_,
                "noise_std": math.sqrt(gp.noise_variance) * gp.y_std_,
                "mean": gp.y_mean_,
                "log_marginal_likelihood": gp.log_marginal_likelihood_value_,
                "restarts": gp.n_restarts,
            }
            for name, gp in zip(loaded.output_names, gps, strict=True)
        ],
        "constraints": loaded.constraints,
        "provenance": loaded.provenance,
    }


def _load_or_report(model: str | None) -> Surrogate | None:
    try:
        return load_surrogate(model)
    except ModelFileError as exc:
        print(f"nearsub surrogate: {exc}", file=sys.stderr)
        return None


def info_command(args) -> int:
    surrogate = _load_or_report(args.model)
    if surrogate is None:
        return 2
    info = describe(surrogate)
    if args.json:
        print(json.dumps(info))
        return 0
    outputs = [o["name"] for o in info["outputs"]]
    print(f"model       {info['model']}")
    print(f"model id    {info['model_id']}  (format version {info['format_version']}, saved {info['saved_utc']})")
    print(f"kind        {info['kind']}" + ("  (prediction = exact LF + residual GP)" if info["low_fidelity"] else ""))
    if info["low_fidelity"]:
        lf = info["low_fidelity"]
        print(
            f"LF          {lf['module']}.{lf['function']} version {lf['version']}, N_STRIPS {lf['n_strips']}, "
            f"N_FRUSTA {lf['n_frusta']} (hash {lf['hash']})"
        )
    print(f"training    {info['training_points']} points, {len(info['inputs'])} inputs, {len(outputs)} outputs")
    from rich.table import Table

    from ..support import tables

    console = tables.console()
    print(f"inputs, with the GP's length scales in (warped) input units ({', '.join(outputs)})")
    table = Table("input", "unit")
    for name in ("lower", "upper"):
        table.add_column(name, justify="right")
    table.add_column("warping", no_wrap=True)
    for name in outputs:
        table.add_column(name, justify="right")
    for item in info["inputs"]:
        lower, upper = (f"{v:g}" for v in item["bounds"])
        scales = [f"{v:.3g}" for v in item["length_scales"].values()]
        table.add_row(item["name"], item["unit"], lower, upper, item["warping"], *scales)
    console.print(table)
    table = Table("output")
    for name in ("mean", "signal std", "noise std", "log ML", "starts"):
        table.add_column(name, justify="right")
    table.add_column("unit", no_wrap=True)
    for o in info["outputs"]:
        table.add_row(o["name"], f"{o['mean']:.3g}", f"{o['signal_std']:.3g}", f"{o['noise_std']:.3g}",
                      f"{o['log_marginal_likelihood']:.1f}", str(o["restarts"]), o["unit"])  # fmt: skip
    console.print(table)
    print("constraints")
    for name, text in info["constraints"].items():
        print(f"  {name}: {text}")
    print("provenance")
    for name, value in info["provenance"].items():
        print(f"  {name}: {value}")
    return 0


# ------------------------------------------------------------------------------- predict
POSITIVE_INPUTS = ("u_kn", "d_ratio", "ld_ratio")


def parse_point(items: list[str]) -> tuple[str | None, np.ndarray]:
    """[MODEL] NAME=VALUE ... -> (model path or None, the point in INPUT_NAMES order).
    Raises ValueError naming the unknown, missing, unreadable or impossible inputs: a value must be
    finite, and the speed and hull ratios above zero (the physics divides by them)."""
    model = items[0] if items and "=" not in items[0] else None
    values: dict[str, float] = {}
    for item in items[1:] if model is not None else items:
        name, sep, text = item.partition("=")
        if not sep or name not in INPUT_NAMES:
            raise ValueError(f"expected NAME=VALUE with NAME one of {', '.join(INPUT_NAMES)}, got {item!r}")
        try:
            values[name] = float(text)
        except ValueError:
            raise ValueError(f"{name}: not a number: {text!r}") from None
        if not math.isfinite(values[name]):
            raise ValueError(f"{name}={text}: not a finite number")
        if name in POSITIVE_INPUTS and not values[name] > 0.0:
            raise ValueError(f"{name}={text}: must be > 0 (no UUV has that speed or size)")
    missing = [name for name in INPUT_NAMES if name not in values]
    if missing:
        raise ValueError(f"missing inputs: {', '.join(missing)}")
    return model, np.array([values[name] for name in INPUT_NAMES])


def predict_command(args) -> int:
    try:
        model, point = parse_point(args.items)
    except ValueError as exc:
        print(f"nearsub surrogate predict: {exc}", file=sys.stderr)
        return 2
    surrogate = _load_or_report(model)
    if surrogate is None:
        return 2
    p = surrogate.predict(point)
    outside = [
        name for name, x, (low, high) in zip(INPUT_NAMES, point, surrogate.bounds, strict=True) if not low <= x <= high
    ]
    violated = [name for name, g in zip(CONSTRAINT_NAMES, constraint_values(point)[0], strict=True) if not g >= 0.0]
    result = {
        "model_id": surrogate.model_id,
        "inputs": dict(zip(INPUT_NAMES, point.tolist(), strict=True)),
        "mean": dict(zip(surrogate.output_names, p.mean[0].tolist(), strict=True)),
        "std": dict(zip(surrogate.output_names, p.std[0].tolist(), strict=True)),
        "in_domain": bool(p.in_domain[0]),
        "constraints_ok": bool(p.constraints_ok[0]),
        "outside_bounds": outside,
        "violated_constraints": violated,
    }
    if args.json:
        print(json.dumps(result))
        return 0
    for name in surrogate.output_names:
        print(f"{name} = {result['mean'][name]: .6e} +/- {result['std'][name]:.2e}")
    print("in domain (table 4.2):   " + ("yes" if not outside else f"NO, outside: {', '.join(outside)}"))
    print("constraints (4.4)-(4.7): " + ("ok" if not violated else f"VIOLATED: {', '.join(violated)}"))
    if outside or violated:
        print("(answered with the GP's value at this point; it is not trained there)")
    return 0


# ------------------------------------------------------------------------------ validate
PANEL_CHOICES = ("coarse", "medium", "fine")  # hydro_hf.COARSE, MEDIUM, FINE
_EQUIVALENT_LABELS = ("{:.2f} % X_prop", "d_eq,Y = {:.2f} deg", "d_eq,N = {:.2f} deg")


def _write_validation(path: Path, result: dict) -> None:
    """The result as JSON (summary and every point) or CSV (one row per test point)."""
    if path.suffix == ".json":
        path.write_text(json.dumps(result, indent=1) + "\n")
        return
    names = result["summary"]["outputs"]
    columns = [*INPUT_NAMES, *(f"{n}_hf" for n in names), *(f"{n}_pred" for n in names), *(f"{n}_std" for n in names)]
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow([*columns, "hf_seconds"])
        for row in result["rows"]:
            writer.writerow([*(row[c] for c in columns), row["hf_seconds"]])


def format_validation(result: dict) -> str:
    """The MAE table in the form of thesis table 4.3, the model next to the LF alone and the thesis,
    with the relative MAE (over the mean |HF|) and the 2-sigma coverage."""
    s = result["summary"]
    lines = [f"surrogate validation: {result['model']} (model id {result['model_id']}, kind {result['kind']})"]
    left_out = (
        "" if s["evaluated"] == s["points"] else f"; {s['points'] - s['evaluated']} left out (HF or LF undefined)"
    )
    if result.get("points_file"):
        lines.append(f"test set: {s['points']} points with HF values from {result['points_file']}{left_out}")
    else:
        cost = result["hf_seconds_per_point"]
        lines += [
            f"test set: {s['points']} Latin-hypercube points within (4.4)-(4.7), seed {result['seed']}{left_out}",
            f"high fidelity: hydro_hf {result['panels'].upper()} panels, {cost['mean']:.2f} s a point "
            f"(median {cost['median']:.2f}, max {cost['max']:.2f}; {result['jobs']} job(s), "
            f"{result['wall_seconds']:.0f} s wall)",
        ]
    lines += [
        "",
        f"{'output':<7} {'model MAE':>10} {'rel.':>6}  {'LF MAE':>10} {'rel.':>6}  {'LF/model':>8}  {'2-sigma':>7}"
        f"  {'thesis MAE':>10}   equivalent (REMUS 100)",
    ]
    for k, name in enumerate(("X'", "Y'", "N'")):
        lines.append(
            f"{name:<7} {s['mae'][k]:>10.3e} {100 * s['relative_mae'][k]:>5.1f}%  {s['lf_mae'][k]:>10.3e} "
            f"{100 * s['lf_relative_mae'][k]:>5.1f}%  {s['lf_over_model'][k]:>8.2f}  "
            f"{100 * s['fraction_within_2_std'][k]:>6.1f}%  {s['thesis_mae'][k]:>10.3e}   "
            + _EQUIVALENT_LABELS[k].format(s["equivalents"][k])
        )
    through = s["thesis_mae_through_this_conversion"]
    lines += [
        "",
        "rel. = MAE / mean |HF value|; LF = the exact low fidelity alone;",
        "2-sigma = share of the errors within 2 predicted std",
        "equivalents: force = coefficient x 0.5 rho u^2 L^2 (L^3 for N) (section 5.2) over the REMUS 100's rudder",
        "  force Y_uu_dr u^2, moment N_uu_dr u^2 and steady thrust -X_u|u| u^2 ((5.11), Prestero); u cancels.",
        f"  The thesis's MAEs (its equivalents {', '.join(f'{v:g}' for v in s['thesis_equivalents'])}) through the "
        f"same conversion: {through[0]:.1f} % X_prop, {through[1]:.2f} deg, {through[2]:.2f} deg.",
        "context (mean |HF value|, largest error):",
        *(
            f"  {name:<5} {m:>10.2e} {e:>10.2e}"
            for name, m, e in zip(("X'", "Y'", "N'"), s["mean_abs_hf"], s["max_abs_error"], strict=True)
        ),
    ]
    return "\n".join(lines)


def validate_command(args) -> int:
    out = Path(args.out) if args.out else None
    if out is not None and out.suffix not in (".json", ".csv"):
        print(f"nearsub surrogate validate: --out {out}: expected a .json or .csv file", file=sys.stderr)
        return 2
    if args.points < 1 or args.jobs < 1:
        print(
            f"nearsub surrogate validate: --points and --jobs must be >= 1, got {args.points}, {args.jobs}",
            file=sys.stderr,
        )
        return 2
    if out is not None:
        output_file(out, "--out", source=args.points_file, source_is="the --points-file it reads", parents=True)
    X = Y_hf = None
    if args.points_file:
        try:
            X, Y_hf = read_points_file(args.points_file)
        except PointsFileError as exc:
            print(f"nearsub surrogate validate: --points-file {exc}", file=sys.stderr)
            return 2
    surrogate = _load_or_report(args.model)
    if surrogate is None:
        return 2
    started = time.perf_counter()
    if X is None:
        X = latin_hypercube_feasible(args.points, args.seed)
        from nearsub.common.hydro import (
            high_fidelity as hydro_hf,  # imported here: the panel code is not needed to build the parser
        )

        hf = functools.partial(hydro_hf.hf_coefficients, panels=getattr(hydro_hf, args.panels.upper()))
        with Progress(
            TextColumn("[bold]HF test points"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeRemainingColumn(),
            disable=not sys.stderr.isatty(),
        ) as progress:
            task = progress.add_task("validate", total=len(X))
            Y_hf, seconds = evaluate_rows(hf, X, args.jobs, on_row=lambda _: progress.advance(task))
    else:
        seconds = np.full(len(X), np.nan)
    wall = time.perf_counter() - started
    p = surrogate.predict(X)
    names = list(surrogate.output_names)
    result = {
        "model": surrogate.source,
        "model_id": surrogate.model_id,
        "kind": surrogate.kind,
        "points_file": args.points_file,
        "panels": args.panels,
        "seed": args.seed,
        "jobs": args.jobs,
        "wall_seconds": wall,
        "summary": validation_summary(X, Y_hf, p.mean, p.std),
        "rows": [
            {
                **dict(zip(INPUT_NAMES, x.tolist(), strict=True)),
                **{f"{n}_hf": float(v) for n, v in zip(names, y, strict=True)},
                **{f"{n}_pred": float(v) for n, v in zip(names, m, strict=True)},
                **{f"{n}_std": float(v) for n, v in zip(names, e, strict=True)},
                "hf_seconds": float(t),
            }
            for x, y, m, e, t in zip(X, Y_hf, p.mean, p.std, seconds, strict=True)
        ],
    }
    if not args.points_file:
        result["hf_seconds_per_point"] = {
            "mean": float(np.mean(seconds)),
            "median": float(np.median(seconds)),
            "max": float(np.max(seconds)),
        }
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        _write_validation(out, result)
    if args.json:
        print(json.dumps({k: v for k, v in result.items() if k != "rows"}))
    else:
        print(format_validation(result))
        if out is not None:
            print(f"wrote {out}")
    return 0


def calibrate_command(args) -> int:
    """Scale each output's std by the factor its leave-one-out z-scores ask for; write a new file."""
    source = Path(args.model) if args.model else default_model_path()
    out = output_file(args.out, "-o", source=source, source_is="the model it reads")
    if not 0.5 < args.coverage < 1.0:
        print(
            f"nearsub surrogate calibrate: --coverage {args.coverage}: expected a share between 0.5 and 1",
            file=sys.stderr,
        )
        return 2
    try:
        loaded = load_model(source)
    except (ModelFileError, OSError) as exc:
        print(f"nearsub surrogate calibrate: {exc}", file=sys.stderr)
        return 2
    gps = getattr(loaded.model, "delta", loaded.model).gps
    before = [calibration.loo_z_scores(gp) for gp in gps]
    factors = [calibration.std_factor(z, args.coverage) for z in before]
    getattr(loaded.model, "delta", loaded.model).scale_std(factors)
    after = [calibration.loo_z_scores(gp) for gp in gps]
    rows = [
        {
            "output": name,
            "factor": c,
            "loo_coverage_before": calibration.coverage(z0),
            "loo_coverage_after": calibration.coverage(z1),
        }
        for name, c, z0, z1 in zip(loaded.output_names, factors, before, after, strict=True)
    ]
    provenance = dict(loaded.provenance)
    provenance["std_calibration"] = {
        "method": "leave-one-out z-scores of the residual GP (common/surrogate/calibration.py)",
        "target_coverage": args.coverage,
        "calibrated_from": str(source),
        "outputs": rows,
    }
    save_model(
        out,
        loaded.model,
        input_names=loaded.input_names,
        output_names=loaded.output_names,
        units=loaded.units,
        bounds=loaded.bounds,
        constraints=loaded.constraints,
        provenance=provenance,
    )
    print(f"{'output':8} {'factor':>7} {'LOO 2-sigma coverage':>22}")
    for row in rows:
        before_after = f"{row['loo_coverage_before']:.1%} -> {row['loo_coverage_after']:.1%}"
        print(f"{row['output']:8} {row['factor']:7.3f} {before_after:>22}")
    print(f"wrote {out}")
    return 0


# --------------------------------------------------------------------------------- bench
def _times(call: Callable[[], object], repeats: int) -> np.ndarray:
    """Wall seconds of each of `repeats` calls."""
    out = np.empty(repeats)
    for i in range(repeats):
        start = time.perf_counter()
        call()
        out[i] = time.perf_counter() - start
    return out


def bench_surrogate(args) -> int:
    X = sample_feasible(10_000, seed=1)
    X_train = sample_feasible(100, seed=0)
    Y_train = analytic_coefficients(X_train)
    with tempfile.TemporaryDirectory(prefix="nearsub-bench-") as folder:
        path = write_analytic_model(Path(folder) / "analytic.npz", n=100)
        surrogate = Surrogate(load_model(path))
        point = X[:1]
        _times(lambda: surrogate.predict(point), 200)  # warm-up
        core = _times(lambda: surrogate.model.predict_point(point[0]), args.repeats)
        flagged = _times(lambda: surrogate.predict(point), args.repeats)
        batch = _times(lambda: surrogate.predict(X), 10)
        community = f"benchsurrogate{os.getpid()}"
        with local_server(path, community) as (bus, _):
            querier = bus.querier(surrogate_key(community), timeout=2.0)
            one, thousand = encode_query(point), encode_query(X[:1000])
            # The sim's path: the published request/reply pair (apps.services.RemoteSurrogate).
            remote = RemoteSurrogate(bus, community)
            _times(lambda: (querier.ask(one), remote.predict(point)), 200)  # warm-up: connections, caches
            # The two paths in alternation, so a machine's changing load weighs on both alike.
            query, published = np.empty(args.repeats), np.empty(args.repeats)
            for i in range(args.repeats):
                query[i] = _times(lambda: decode_reply(querier.ask(one)), 1)[0]
                published[i] = _times(lambda: remote.predict(point), 1)[0]
            query_batch = _times(lambda: decode_reply(querier.ask(thousand)), 20)
            same = np.array_equal(decode_reply(querier.ask(one)).prediction().mean, surrogate.predict(point).mean)
            same = same and np.array_equal(remote.predict(point).mean, surrogate.predict(point).mean)
    shipped = load_surrogate()
    in_loop = None
    if shipped.kind == "lf_in_loop":
        shipped.predict(point)  # warm-up: builds the LF's submarine field
        in_loop = {
            "model": f"{shipped.source} ({shipped.kind}, {len(shipped.model.X)} HF samples)",
            "point_us": statistics.median(_times(lambda: shipped.predict(point), args.repeats // 4)) * 1e6,
            "lf_point_us": statistics.median(_times(lambda: shipped.low_fidelity(point), args.repeats // 4)) * 1e6,
            "batch_10000_ms": statistics.median(_times(lambda: shipped.predict(X), 3)) * 1e3,
        }
    fit3 = _times(lambda: MultiOutputGP(bounds=BOUNDS, n_restarts=5).fit(X_train, Y_train), args.fit_repeats)
    fit1 = _times(lambda: GaussianProcess(bounds=BOUNDS, n_restarts=5).fit(X_train, Y_train[:, 1]), args.fit_repeats)
    med = statistics.median
    result = {
        "model": "analytic fixture: 100 training points, 6 inputs, 3 outputs",
        "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
        "point_core_us": med(core) * 1e6,
        "point_flagged_us": med(flagged) * 1e6,
        "batch_10000_ms": med(batch) * 1e3,
        "query_median_us": med(query) * 1e6,
        "query_p99_us": float(np.percentile(query, 99)) * 1e6,
        "query_1000_points_ms": med(query_batch) * 1e3,
        "published_median_us": med(published) * 1e6,
        "published_p99_us": float(np.percentile(published, 99)) * 1e6,
        "query_equals_inprocess": bool(same),
        "fit_3_outputs_s": med(fit3),
        "fit_1_output_s": med(fit1),
        "lf_in_loop": in_loop,
        "targets": TARGETS,
    }
    if args.json:
        print(json.dumps(result))
        return 0

    def row(label: str, value: float, unit: str, target: float | None = None) -> None:
        verdict = "" if target is None else f"target <= {target:g} {unit}  " + ("ok" if value <= target else "MISSED")
        print(f"  {label:<52} {value:9.1f} {unit:<3} {verdict}")

    print(f"surrogate bench: {result['model']}; OPENBLAS_NUM_THREADS={result['blas_threads']}")
    row("in-process point, mean+std of 3 outputs (GP core)", result["point_core_us"], "us", TARGETS["point_us"])
    row("in-process point with domain flags (Surrogate)", result["point_flagged_us"], "us")
    row("in-process batch of 10,000 points, mean+std+flags", result["batch_10000_ms"], "ms", TARGETS["batch_ms"])
    row("Zenoh query round trip, 1 point: median", result["query_median_us"], "us", TARGETS["query_median_us"])
    row("Zenoh query round trip, 1 point: p99", result["query_p99_us"], "us", TARGETS["query_p99_us"])
    row("Zenoh query round trip, 1,000 points: median", result["query_1000_points_ms"], "ms")
    row(
        "published request/reply (the sim's), 1 point: median",
        result["published_median_us"],
        "us",
        TARGETS["query_median_us"],
    )
    row("published request/reply (the sim's), 1 point: p99", result["published_p99_us"], "us", TARGETS["query_p99_us"])
    row("fit, 5 restarts, n = 100, d = 6, 3 outputs", result["fit_3_outputs_s"], "s", TARGETS["fit_s"])
    row("fit, 5 restarts, n = 100, d = 6, 1 output", result["fit_1_output_s"], "s")
    print(f"  query and published replies equal the in-process prediction: {'yes' if same else 'NO'}")
    if in_loop is not None:
        print(f"shipped model: {in_loop['model']}")
        row("in-process point, LF + residual GP, with flags", in_loop["point_us"], "us", TARGETS["lf_in_loop_point_us"])
        row("  of which the exact LF", in_loop["lf_point_us"], "us")
        row("in-process batch of 10,000 points, LF + residual GP", in_loop["batch_10000_ms"], "ms")
    return 0


# ------------------------------------------------------------------------------- parsers
def sweep_command(args) -> int:
    """HF, LF and the applied increment along the heading and lateral sweeps of surrogate/sweeps.py."""
    from nearsub.common.analysis.envelope import surrogate_window
    from nearsub.common.hydro.high_fidelity import COARSE, MEDIUM
    from nearsub.common.physics.vehicles import get_vehicle
    from nearsub.common.surrogate import sweeps

    from ..sweep_figures import draw_sweeps

    surrogate = _load_or_report(args.model)
    if surrogate is None:
        return 2
    if surrogate.kind != "lf_in_loop":
        print(
            f"nearsub surrogate sweep: {surrogate.source} is a {surrogate.kind} model; the sweep shows the "
            "increment of an LF-in-the-loop model",
            file=sys.stderr,
        )
        return 2
    hf_rows = None
    if args.hf_from:
        try:
            with open(args.hf_from, newline="") as handle:
                hf_rows = list(csv.DictReader(handle))
        except (OSError, UnicodeDecodeError) as exc:
            print(f"nearsub surrogate sweep: --hf-from {args.hf_from}: {exc}", file=sys.stderr)
            return 2
    out = output_folder(args.out)
    table = output_file(out / "sweeps.csv", "-o", source=args.hf_from, source_is="the --hf-from it reads", parents=True)
    started = time.perf_counter()
    try:
        rows = sweeps.sweep_table(
            surrogate, get_vehicle("sdv"), COARSE if args.panels == "coarse" else MEDIUM, hf_rows=hf_rows
        )
    except ValueError as exc:
        print(f"nearsub surrogate sweep: --hf-from {args.hf_from}: {exc}", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)  # only now: a refused --hf-from leaves no empty folder
    with open(table, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    window = surrogate_window("sdv")
    for path in [table, *draw_sweeps(rows, out, window)]:
        print(path)
    print(f"{len(rows)} points in {time.perf_counter() - started:.0f} s", file=sys.stderr)
    return 0


def add_parser(subparsers) -> None:
    """Register `surrogate info`, `predict`, `validate`, `sweep` and `calibrate` on the `nearsub` command line."""
    p = subparsers.add_parser("surrogate", help="inspect and query a surrogate model file")
    sub = p.add_subparsers(dest="surrogate_command", required=True)
    t = sub.add_parser("info", help="inputs, bounds, training size, hyperparameters and provenance")
    t.add_argument("model", nargs="?", help="model file (default: the shipped model)")
    t.add_argument("--json", action="store_true")
    t.set_defaults(func=info_command)
    t = sub.add_parser(
        "predict",
        help="mean +/- std of X', Y', N' at one point, with the domain flags",
        usage=f"nearsub surrogate predict [-h] [--json] [MODEL] {' '.join(n + '=...' for n in INPUT_NAMES)}",
    )
    t.add_argument(
        "items", nargs="+", metavar="ARG", help="optional model file, then NAME=VALUE for each of the six inputs"
    )
    t.add_argument("--json", action="store_true")
    t.set_defaults(func=predict_command)
    t = sub.add_parser(
        "validate",
        help="MAE against the high fidelity on Latin-hypercube test points (thesis table 4.3)",
        description="Evaluate the HF physics at Latin-hypercube points within (4.4)-(4.7) and print the MAE of "
        "X', Y', N' with REMUS 100 error equivalents next to thesis table 4.3. Compare with the panels the "
        "model was trained on (the shipped model: medium), or the MAE includes the mesh difference.",
    )
    t.add_argument("model", nargs="?", help="model file (default: the shipped model)")
    t.add_argument("--points", type=int, default=THESIS_TEST_POINTS, help="test points (default 500, as the thesis)")
    t.add_argument("--panels", choices=PANEL_CHOICES, default="medium", help="HF panel spec (default medium)")
    t.add_argument(
        "--seed",
        type=integer(minimum=0),
        default=HELD_OUT_SEED,
        help=f"seed of the Latin hypercube (default {HELD_OUT_SEED})",
    )
    t.add_argument("--jobs", type=int, default=1, help="HF processes (default 1)")
    t.add_argument(
        "--points-file",
        metavar="CSV",
        help="test inputs with their HF values (columns as docs/hydro/validation-points.csv: the inputs and "
        "X_p_hf, Y_p_hf, N_p_hf): no HF runs; --points, --seed, --panels, --jobs are then unused",
    )
    t.add_argument("--out", help="write the result: .json (summary and points) or .csv (points)")
    t.add_argument("--json", action="store_true", help="print the summary as JSON")
    t.set_defaults(func=validate_command)
    t = sub.add_parser(
        "sweep",
        help="the interaction increment along heading and lateral sweeps: HF, LF and what the sim applies",
    )
    t.add_argument("model", nargs="?", help="model file (default: the shipped model)")
    t.add_argument("--panels", choices=("coarse", "medium"), default="medium", help="HF panels (default medium)")
    t.add_argument("-o", "--out", default="sweeps", help="folder for sweeps.csv and the PNGs (default: ./sweeps)")
    t.add_argument(
        "--hf-from",
        metavar="CSV",
        help="take the HF increments from an earlier sweeps.csv at the same panels instead of running the HF",
    )
    t.set_defaults(func=sweep_command)
    t = sub.add_parser(
        "calibrate",
        help="scale the predicted std so its two-sigma band covers the leave-one-out errors (a new file)",
        description="Scale each output's std by one factor, chosen so that --coverage of the residual GP's "
        "leave-one-out errors fall within two std; the mean is unchanged. Writes a new model file.",
    )
    t.add_argument("model", nargs="?", help="model file (default: the shipped model)")
    t.add_argument("-o", "--out", required=True, help="the calibrated model file to write (never the input)")
    t.add_argument(
        "--coverage",
        type=float,
        default=calibration.TARGET_COVERAGE,
        help=f"two-sigma coverage of the leave-one-out errors to aim at (default {calibration.TARGET_COVERAGE}, "
        "a Gaussian's)",
    )
    t.set_defaults(func=calibrate_command)


def add_bench_parser(bench_subparsers) -> None:
    """Register `bench surrogate`."""
    t = bench_subparsers.add_parser("surrogate", help="surrogate prediction, query round trip and fit timings")
    t.add_argument(
        "--repeats",
        type=integer(minimum=4),
        default=2000,
        help="timed single-point calls (default 2000; at least 4: a quarter times the shipped model)",
    )
    t.add_argument("--fit-repeats", type=integer(minimum=1), default=3, help="timed fits (default 3)")
    t.add_argument("--json", action="store_true")
    t.set_defaults(func=bench_surrogate)
