"""`nearsub bench`: benchmarks that print what they measured.

`pipeline` runs a mission (alpha by default) at warp 0 through the multi-process launcher and
in one process, and reports lock-stepped steps per second and their ratio.

`envelope` times one operating envelope in the batch engine (vehicle-steps per second), the same
cells flown one by one in-process (a sample, extrapolated) and the whole `--thesis-figures` set.

`surrogate` times the surrogate's predictions and queries; `hydro` the cost of the LF and HF models.
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

from .envelope import grid_size

DEFAULT_MISSION = Path(__file__).resolve().parents[1] / "missions" / "alpha.toml"


def add_parser(subparsers) -> None:
    from .helm_bench import add_bench_parser as add_helm_bench_parser
    from .surrogate import add_bench_parser

    p = subparsers.add_parser("bench")
    b = p.add_subparsers(dest="bench_command", required=True)
    t = b.add_parser("pipeline", help="lock-stepped steps per second of a mission at warp 0")
    t.add_argument("--mission", default=None, help="mission file (default: missions/alpha.toml)")
    t.add_argument("--repeats", type=int, default=3)
    t.add_argument("--json", action="store_true")
    t.set_defaults(func=bench_pipeline)
    add_bench_parser(b)
    add_envelope_bench_parser(b)
    add_helm_bench_parser(b)
    t = b.add_parser("hydro", help="cost per evaluation of the low- and high-fidelity hydrodynamic models")
    t.set_defaults(func=bench_hydro)


def inprocess_rate(mission_path: Path) -> tuple[float, int]:
    from nearsub.common.mission.cores import build_cores
    from nearsub.common.mission.schema import load_mission
    from nearsub.common.runtime.lifecycle import Schedule, run_inprocess

    mission = load_mission(mission_path)
    start = time.perf_counter()
    result = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    return result.steps / (time.perf_counter() - start), result.steps


def children_cpu() -> float:
    """CPU seconds (user + system) of every child process that has ended."""
    import resource

    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def pipeline_rate(mission_path: Path, log_dir: str, index: int, *overrides: str) -> tuple[float, int, str, float]:
    """Steps per second of one launch, its steps and outcome, and the CPU seconds of all the
    processes it started."""
    from nearsub.common.mission.schema import load_mission

    from .launcher import Launcher

    mission = load_mission(mission_path, [f"name=bench{index}_{int(time.time())}", "warp=0", *overrides])
    cpu = children_cpu()
    summary = Launcher(mission, str(mission_path), log_dir, quiet=True).run()
    return summary.steps_per_second, summary.steps, summary.outcome, children_cpu() - cpu


def bench_pipeline(args) -> int:
    mission_path = Path(args.mission) if args.mission else DEFAULT_MISSION
    rates, cpus = [], []
    with tempfile.TemporaryDirectory() as log_dir:
        # A launch of a few steps costs the start-up and shutdown: the CPU per step is what a
        # full run costs beyond it.
        _, short_steps, _, fixed_cpu = pipeline_rate(mission_path, log_dir, args.repeats, "time_limit=0.5")
        for index in range(args.repeats):
            rate, steps, outcome, cpu = pipeline_rate(mission_path, log_dir, index)
            if outcome not in ("completed", "time_limit"):
                print(f"nearsub bench: run {index} ended with {outcome}", file=sys.stderr)
                return 1
            rates.append(rate)
            cpus.append((cpu - fixed_cpu) * 1e3 / max(steps - short_steps, 1))
            if not args.json:
                line = f"{steps} steps, {rate:.0f} steps/s, {cpus[-1]:.2f} CPU-ms per step (all processes)"
                print(f"  multi-process run {index + 1}: {line}", file=sys.stderr)
    local = [inprocess_rate(mission_path)[0] for _ in range(args.repeats)]
    result = {
        "mission": str(mission_path),
        "repeats": args.repeats,
        "pipeline_steps_per_second": {"median": statistics.median(rates), "min": min(rates), "max": max(rates)},
        "pipeline_cpu_ms_per_step": {"median": statistics.median(cpus), "min": min(cpus), "max": max(cpus)},
        "inprocess_steps_per_second": {"median": statistics.median(local)},
        "ratio_inprocess_over_pipeline": statistics.median(local) / statistics.median(rates),
        "target_steps_per_second": 1000,
    }
    if args.json:
        print(json.dumps(result))
    else:
        p = result["pipeline_steps_per_second"]
        spread = f"min {p['min']:.0f}, max {p['max']:.0f}"
        print(f"lock-stepped pipeline: median {p['median']:.0f} steps/s ({spread}) over {args.repeats} runs")
        c = result["pipeline_cpu_ms_per_step"]
        print(f"CPU per step:          median {c['median']:.2f} ms over all processes (start-up and shutdown apart)")
        print(f"in-process loop:       median {result['inprocess_steps_per_second']['median']:.0f} steps/s")
        print(f"in-process / pipeline: {result['ratio_inprocess_over_pipeline']:.1f}x   (target: >= 1000 steps/s)")
    return 0


def add_envelope_bench_parser(bench_subparsers) -> None:
    t = bench_subparsers.add_parser("envelope", help="envelope wall time, vehicle-steps/s, speed-up, thesis set")
    t.add_argument("--vehicle", default="remus100", help="vehicle of the timed envelope (default remus100)")
    t.add_argument("--grid", type=grid_size, default=(40, 20), metavar="NxM", help="cells (default 40x20 = 800)")
    t.add_argument("--duration", type=float, default=120.0, help="simulated seconds per cell (default 120)")
    t.add_argument("--repeats", type=int, default=3, help="timed envelopes (default 3)")
    t.add_argument("--sample", type=int, default=10, help="cells flown one by one in-process (default 10)")
    t.add_argument("--skip-thesis", action="store_true", help="do not time the --thesis-figures set")
    t.add_argument("--workers", type=int, help="time the thesis set on a local Dask cluster of N workers")
    t.add_argument("--json", action="store_true")
    t.set_defaults(func=bench_envelope)


def bench_envelope(args) -> int:
    """Wall time of one envelope, the batch engine's speed-up over single in-process missions (from
    an evenly spread sample of feasible cells) and the time of the thesis figure set."""
    import os

    import numpy as np

    from nearsub.common.analysis import envelope as env
    from nearsub.common.analysis.batch import OUTCOMES
    from nearsub.common.mission.cores import run_mission

    n_long, n_lat = args.grid
    config = env.EnvelopeConfig(vehicle=args.vehicle, grid=(n_long, n_lat), duration=args.duration)
    surrogate = env.cached_surrogate(config.model)
    env.compute_envelope(config.model_copy(update={"grid": (2, 2), "duration": 1.0}), surrogate)  # warm caches
    load_before = os.getloadavg()[0]
    times, found = [], None
    for _ in range(args.repeats):
        found = env.compute_envelope(config, surrogate)
        times.append(found.wall_time)
    vehicle_steps = int(found.result.steps.sum())
    x, y = env.cell_positions(config)
    feasible = np.flatnonzero(found.result.outcome != OUTCOMES.index("infeasible"))
    sample = feasible[np.linspace(0, len(feasible) - 1, min(args.sample, len(feasible))).astype(int)]
    began = time.perf_counter()
    sample_steps = 0
    for k in sample:
        sample_steps += run_mission(env.cell_mission(config, x[k], y[k]), surrogate).steps
    per_step_single = (time.perf_counter() - began) / sample_steps
    one_by_one = per_step_single * vehicle_steps  # the same cells, one mission after another
    median = statistics.median(times)
    result = {
        "cells": n_long * n_lat,
        "feasible_cells": len(feasible),
        "duration_s": config.duration,
        "dt": config.dt,
        "vehicle": config.vehicle,
        "envelope_wall_s": {"median": round(median, 2), "min": round(min(times), 2), "max": round(max(times), 2)},
        "vehicle_steps": vehicle_steps,
        "vehicle_steps_per_second": round(vehicle_steps / median),
        "one_by_one_in_process_s": round(one_by_one, 1),
        "one_by_one_sample_cells": len(sample),
        "speed_up": round(one_by_one / median, 1),
        "load_average_before": round(load_before, 2),
        "target_envelope_s": 10.0,
    }
    if not args.skip_thesis:
        figures = env.thesis_figures()
        configs = env.unique_configs(figures)
        began = time.perf_counter()
        done = env.sweep(configs, workers=args.workers)
        result["thesis_figures"] = {
            "configurations": len(configs),
            "wall_s": round(time.perf_counter() - began, 1),
            "vehicle_steps": int(sum(e.result.steps.sum() for e in done)),
            "workers": args.workers or "this process",
            "target_s": 600.0,
        }
    result["load_average_after"] = round(os.getloadavg()[0], 2)
    if args.json:
        print(json.dumps(result))
        return 0
    wall = result["envelope_wall_s"]
    print(
        f"envelope ({result['cells']} cells, {len(feasible)} feasible, {config.duration:g} s at dt {config.dt:g}, "
        f"{config.vehicle}): median {wall['median']:.2f} s (min {wall['min']:.2f}, max {wall['max']:.2f}) "
        f"over {args.repeats} runs   (target: <= 10 s)"
    )
    print(f"  {vehicle_steps} vehicle-steps, {result['vehicle_steps_per_second']} vehicle-steps/s")
    print(
        f"  the same cells one by one in-process: ~{one_by_one:.0f} s (from {len(sample)} cells), "
        f"speed-up {result['speed_up']:.0f}x"
    )
    if "thesis_figures" in result:
        t = result["thesis_figures"]
        print(f"--thesis-figures set: {t['configurations']} envelopes in {t['wall_s']:.0f} s   (target: <= 600 s)")
    print(f"  load average {result['load_average_before']} before, {result['load_average_after']} after (2 cores)")
    return 0


def bench_hydro(args) -> int:
    from .hydro_bench import benchmark_fidelities

    benchmark_fidelities()
    return 0
