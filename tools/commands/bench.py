"""`nearsub bench`: benchmarks that print what they measured.

`pipeline` runs missions (alpha and overtake_stern_nuv by default) at warp 0 through the
multi-process launcher and in one process, and reports lock-stepped steps per second, the CPU per
step of each process and start-up and shutdown times, then flies alpha beside MOOS-IvP's own alpha
at warp 25 and 50 where MOOS-IvP is installed (tools/moos_alpha.py).

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
from collections.abc import Sequence
from pathlib import Path

from .. import moos_alpha
from ..support.arguments import integer, number
from ..support.errors import InputError
from .envelope import grid_size

DEFAULT_MISSION = Path(__file__).resolve().parents[2] / "missions" / "alpha.toml"
NUV_MISSION = DEFAULT_MISSION.with_name("overtake_stern_nuv.toml")  # submarine, surrogate server, N_uv helm


def add_parser(subparsers) -> None:
    from ..helm_bench import add_bench_parser as add_helm_bench_parser
    from .surrogate import add_bench_parser

    p = subparsers.add_parser("bench")
    b = p.add_subparsers(dest="bench_command", required=True)
    t = b.add_parser("pipeline", help="lock-stepped steps per second, CPU per app, start-up and shutdown")
    t.add_argument("--mission", default=None, help="one mission file (default: alpha and overtake_stern_nuv)")
    t.add_argument("--repeats", type=integer(minimum=1), default=3)
    t.add_argument(
        "--vehicles",
        type=vehicle_counts,
        metavar="N,N,...",
        help="instead: fleets of N REMUS 100s flying copies of alpha, e.g. 1,4,16 (steps/s, CPU per vehicle-step)",
    )
    t.add_argument(
        "--fleet-time", type=number(above=0.0), default=60.0, metavar="T", help="simulated seconds of each fleet run"
    )
    t.add_argument(
        "--host",
        type=host_share,
        metavar="I/K",
        help="with one --vehicles N: this host's share of a fleet over K hosts on the router of --set "
        "network.connect=...; host 1 runs the clock and logger and reports the rate, the others join "
        "(docs/network.md)",
    )
    t.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a mission setting for every run of the measured missions, as in nearsub launch (e.g. "
        "apps.sim.surrogate=in_process); the MOOS-IvP comparison flies alpha as shipped",
    )
    t.add_argument("--json", action="store_true")
    t.set_defaults(func=bench_pipeline)
    add_bench_parser(b)
    add_envelope_bench_parser(b)
    add_helm_bench_parser(b)
    t = b.add_parser("hydro", help="cost per evaluation of the low- and high-fidelity hydrodynamic models")
    t.set_defaults(func=bench_hydro)


def inprocess_rate(mission) -> tuple[float, int]:
    """Steps per second of `run_inprocess` (the surrogate, when needed, loaded before the clock starts)."""
    from nearsub.common.mission.cores import EncounterCheck, build_cores, build_fleet, mission_surrogate
    from nearsub.common.runtime.lifecycle import Schedule, run_inprocess

    surrogate = mission_surrogate(mission) if mission.needs_surrogate else None
    if mission.fleet:
        cores, schedule, observer = build_fleet(mission, surrogate), mission.lockstep(), EncounterCheck(mission)
    else:
        cores, schedule, observer = build_cores(mission, surrogate), Schedule(mission.periods()), None
    start = time.perf_counter()
    result = run_inprocess(cores, schedule, mission.dt, mission.max_steps, observer=observer)
    return result.steps / (time.perf_counter() - start), result.steps


class MissionFile:
    """A mission file to benchmark, loaded with each run's overrides."""

    def __init__(self, path: Path):
        self.path, self.name = path, path.stem

    def load(self, overrides: list[str]):
        from nearsub.common.mission.schema import load_mission

        return load_mission(self.path, overrides)


class AlphaFleet:
    """N REMUS 100s, each flying alpha's waypoints shifted FLEET_SPACING metres south of the
    previous vehicle's (no two meet), for `nearsub bench pipeline --vehicles`."""

    def __init__(self, count: int, time_limit: float):
        self.count, self.time_limit, self.path = count, time_limit, None
        self.name = f"alpha_x{count}"

    def load(self, overrides: list[str]):
        from nearsub.common.mission.schema import apply_overrides, mission_from_dict, resolve_includes

        data = resolve_includes(DEFAULT_MISSION)
        start, legs = data.pop("start"), data["apps"]["helm"].pop("legs")
        data.pop("vehicle")
        data["time_limit"] = self.time_limit
        # Every process of the fleet imports at once on a shared machine: allow for it.
        data["startup_timeout"] = 60.0 + 10.0 * self.count
        data["vehicles"] = []
        for k in range(self.count):
            dy = -FLEET_SPACING * k
            shifted = [leg | {"points": [[x, y + dy] for x, y in leg["points"]]} for leg in legs]
            entry = {"name": f"auv{k + 1}", "type": "remus100", "start": start | {"y": start["y"] + dy}}
            data["vehicles"].append(entry | {"apps": {"helm": {"legs": shifted}}})
        return mission_from_dict(apply_overrides(data, list(overrides)), self.name, overrides)


FLEET_SPACING = 250.0  # m between two vehicles' copies of alpha (its survey spans 180 m by 160 m)


def launch_once(source, log_dir: str, tag: str, *overrides: str, share: tuple[int, int] | None = None):
    """One launch at warp 0 through the multi-process launcher: its `Summary`. With a `share`
    (I, K) of a fleet over K hosts, this host's vehicles only (`fleet_share`), under a name every
    host derives alike; host 1 runs the mission, the others join it."""
    from ..launcher.supervision import Launcher

    name = f"bench{tag}" if share else f"bench{tag}_{int(time.time())}"
    mission = source.load([f"name={name}", "warp=0", *overrides])
    here = fleet_share(mission.vehicle_names, share) if share else None
    join = bool(share) and share[0] > 1
    return Launcher(mission, source.path and str(source.path), log_dir, quiet=True, here=here, join=join).run()


def fleet_share(names: list[str], share: tuple[int, int]) -> list[str]:
    """Host I of K's vehicles: the I-th of K nearly equal consecutive parts of `names`."""
    index, hosts = share
    size, extra = divmod(len(names), hosts)
    start = (index - 1) * size + min(index - 1, extra)
    return names[start : start + size + (index <= extra)]


def host_share(text: str) -> tuple[int, int]:
    """'1/2' -> (1, 2), for argparse."""
    import argparse

    index, _, hosts = text.partition("/")
    try:
        share = (int(index), int(hosts))
    except ValueError:
        share = (0, 0)
    if not 1 <= share[0] <= share[1]:
        raise argparse.ArgumentTypeError(f"{text!r} is not a host's share I/K with 1 <= I <= K, such as 1/2")
    return share


def median_spread(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def bench_mission(
    source,
    log_dir: str,
    repeats: int,
    verbose: bool,
    settings: Sequence[str] = (),
    share: tuple[int, int] | None = None,
) -> dict | None:
    """Steps per second, CPU-ms per step of each process, start-up and shutdown time of one mission
    (a `MissionFile` or an `AlphaFleet`). A launch of a few steps costs the start-up and shutdown:
    the CPU per step is what a full run costs beyond it (each process's CPU read at the mission
    end); per vehicle-step it is that divided by the vehicles. `settings`: overrides of every run.
    With a `share` of a fleet over hosts (`launch_once`): this host's processes and vehicles."""
    name = source.name
    short = launch_once(source, log_dir, f"{name}_short", *settings, "time_limit=0.5", share=share)
    runs = []
    for index in range(repeats):
        summary = launch_once(source, log_dir, f"{name}{index}", *settings, share=share)
        if summary.outcome not in ("completed", "time_limit", "collision"):
            print(
                f"nearsub bench: {name} run {index + 1} ended with {summary.outcome}: {summary.reason}", file=sys.stderr
            )
            return None
        steps = max(summary.steps - short.steps, 1)
        per_app = {app: (cpu - short.cpu.get(app, 0.0)) * 1e3 / steps for app, cpu in summary.cpu.items()}
        runs.append((summary, per_app))
        if verbose:
            line = (
                f"{summary.steps} steps, {summary.steps_per_second:.0f} steps/s, {sum(per_app.values()):.2f} CPU-ms "
                f"per step (all processes), start-up {summary.startup_time:.2f} s, "
                f"shutdown {summary.shutdown_time:.2f} s"
            )
            print(f"  {name} run {index + 1}: {line}", file=sys.stderr)
    apps = sorted({app for _, per_app in runs for app in per_app})
    mission = source.load(list(settings))
    local = [inprocess_rate(mission)[0] for _ in range(repeats)] if not share else [0.0]
    vehicles = len(fleet_share(mission.vehicle_names, share) if share else mission.vehicle_names)
    return {
        "mission": str(source.path or name),
        "vehicles": vehicles,
        "steps": runs[-1][0].steps,
        "pipeline_steps_per_second": median_spread([s.steps_per_second for s, _ in runs]),
        "pipeline_cpu_ms_per_step": median_spread([sum(per_app.values()) for _, per_app in runs]),
        "cpu_ms_per_vehicle_step": median_spread([sum(per_app.values()) / vehicles for _, per_app in runs]),
        "cpu_ms_per_step_by_app": {app: statistics.median(p.get(app, 0.0) for _, p in runs) for app in apps},
        "startup_s": median_spread([s.startup_time for s, _ in runs] + [short.startup_time]),
        "shutdown_s": median_spread([s.shutdown_time for s, _ in runs] + [short.shutdown_time]),
        "inprocess_steps_per_second": {"median": statistics.median(local)},
    }


def vehicle_counts(text: str) -> list[int]:
    """'1,4,16' -> [1, 4, 16], for argparse."""
    import argparse

    try:
        counts = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        counts = []
    if not counts or any(not 1 <= n <= 64 for n in counts):
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of vehicle counts from 1 to 64, such as 1,4,16")
    return counts


def bench_pipeline(args) -> int:
    import os

    if args.host and (not args.vehicles or len(args.vehicles) > 1):
        raise InputError(
            f"--host {args.host[0]}/{args.host[1]}: give one fleet size with --vehicles, e.g. --vehicles 32"
        )
    if args.vehicles:
        sources = [AlphaFleet(n, args.fleet_time) for n in args.vehicles]
    else:
        sources = [MissionFile(Path(p)) for p in ([args.mission] if args.mission else [DEFAULT_MISSION, NUV_MISSION])]
    from nearsub.common.mission.schema import MissionError

    for source in sources:  # a bad file or --set: one line before any run
        try:
            mission = source.load(args.set)
        except (MissionError, OSError) as exc:
            raise InputError(str(exc)) from None
        if args.host and not mission.network.connect:
            raise InputError(
                f"--host {args.host[0]}/{args.host[1]}: the hosts meet on one router: --set network.connect=..."
            )
    load_before = os.getloadavg()[0]
    result = {
        "repeats": args.repeats,
        "settings": args.set,
        "target_steps_per_second": 1000,
        "target_startup_plus_shutdown_s": 2.0,
    }
    with tempfile.TemporaryDirectory() as log_dir:
        for source in sources:
            measured = bench_mission(source, log_dir, args.repeats, not args.json, args.set, args.host)
            if measured is None:
                return 1
            result[source.name] = measured
    if args.host:
        result["host"] = {"share": list(args.host), "vehicles": fleet_share(mission.vehicle_names, args.host)}
        result["moos_ivp"] = {"ran": False, "reason": "a fleet over hosts: comparison skipped"}
    elif DEFAULT_MISSION in [source.path.resolve() for source in sources if source.path]:
        result["moos_ivp"] = moos_alpha.compare(DEFAULT_MISSION, args.repeats, not args.json)
    else:
        result["moos_ivp"] = {"ran": False, "reason": "it runs beside the alpha mission only: comparison skipped"}
    result["load_average"] = {"before": round(load_before, 2), "after": round(os.getloadavg()[0], 2)}
    if args.json:
        print(json.dumps(result))
        return 0
    for source in sources:
        m = result[source.name]
        p, c = m["pipeline_steps_per_second"], m["pipeline_cpu_ms_per_step"]
        where = f" on host {args.host[0]} of {args.host[1]}, this host's processes" if args.host else ""
        print(f"{source.name} ({m['vehicles']} vehicles{where}, {m['steps']} steps), over {args.repeats} runs:")
        print(f"  lock-stepped pipeline: median {p['median']:.0f} steps/s (min {p['min']:.0f}, max {p['max']:.0f})")
        by_app = ", ".join(f"{app} {ms:.2f}" for app, ms in m["cpu_ms_per_step_by_app"].items())
        if m["vehicles"] > 1:  # one line per process would not fit
            by_app = f"clock {m['cpu_ms_per_step_by_app'].get('clock', 0.0):.2f}"
        v = m["cpu_ms_per_vehicle_step"]
        print(f"  CPU per step:          median {c['median']:.2f} ms over all processes ({by_app})")
        print(f"  CPU per vehicle-step:  median {v['median']:.2f} ms (min {v['min']:.2f}, max {v['max']:.2f})")
        local = m["inprocess_steps_per_second"]["median"]
        if local > 0:
            print(f"  in-process loop:       median {local:.0f} steps/s ({local / p['median']:.1f}x the pipeline)")
        up, down = m["startup_s"], m["shutdown_s"]
        print(
            f"  start-up {up['median']:.2f} s (min {up['min']:.2f}), shutdown {down['median']:.2f} s "
            f"(min {down['min']:.2f})   (target: >= 1000 steps/s, start-up + shutdown <= 2 s)"
        )
    moos_alpha.print_comparison(result["moos_ivp"])
    load = result["load_average"]
    print(f"load average {load['before']} before, {load['after']} after (1 min)")
    return 0


def add_envelope_bench_parser(bench_subparsers) -> None:
    t = bench_subparsers.add_parser("envelope", help="envelope wall time, vehicle-steps/s, speed-up, thesis set")
    t.add_argument("--vehicle", default="remus100", help="vehicle of the timed envelope (default remus100)")
    t.add_argument("--grid", type=grid_size, default=(40, 20), metavar="NxM", help="cells (default 40x20 = 800)")
    t.add_argument("--duration", type=number(above=0.0), default=120.0, help="simulated seconds per cell (default 120)")
    t.add_argument("--repeats", type=integer(minimum=1), default=3, help="timed envelopes (default 3)")
    t.add_argument(
        "--sample", type=integer(minimum=1), default=10, help="cells flown one by one in-process (default 10)"
    )
    t.add_argument("--skip-thesis", action="store_true", help="do not time the --thesis-figures set")
    t.add_argument(
        "--workers", type=integer(minimum=1), help="time the thesis set on a local Dask cluster of N workers"
    )
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
    from ..hydro_bench import benchmark_fidelities

    benchmark_fidelities()
    return 0
