"""`nearsub bench`: benchmarks that print what they measured.

`pipeline` runs a mission (alpha by default) at warp 0 through the multi-process launcher and
in one process, and reports lock-stepped steps per second and their ratio.
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

from nearsub.common.cores import build_cores
from nearsub.common.lifecycle import Schedule, run_inprocess
from nearsub.common.mission import load_mission

from .launch import Launcher

DEFAULT_MISSION = Path(__file__).resolve().parents[1] / "missions" / "alpha.toml"


def inprocess_rate(mission_path: Path) -> tuple[float, int]:
    mission = load_mission(mission_path)
    start = time.perf_counter()
    result = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    return result.steps / (time.perf_counter() - start), result.steps


def pipeline_rate(mission_path: Path, log_dir: str, index: int) -> tuple[float, int, str]:
    mission = load_mission(mission_path, [f"name=bench{index}_{int(time.time())}", "warp=0"])
    summary = Launcher(mission, str(mission_path), log_dir, quiet=True).run()
    return summary.steps_per_second, summary.steps, summary.outcome


def bench_pipeline(args) -> int:
    mission_path = Path(args.mission) if args.mission else DEFAULT_MISSION
    rates = []
    with tempfile.TemporaryDirectory() as log_dir:
        for index in range(args.repeats):
            rate, steps, outcome = pipeline_rate(mission_path, log_dir, index)
            if outcome not in ("completed", "time_limit"):
                print(f"nearsub bench: run {index} ended with {outcome}", file=sys.stderr)
                return 1
            rates.append(rate)
            if not args.json:
                print(f"  multi-process run {index + 1}: {steps} steps, {rate:.0f} steps/s", file=sys.stderr)
    local = [inprocess_rate(mission_path)[0] for _ in range(args.repeats)]
    result = {
        "mission": str(mission_path),
        "repeats": args.repeats,
        "pipeline_steps_per_second": {"median": statistics.median(rates), "min": min(rates), "max": max(rates)},
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
        print(f"in-process loop:       median {result['inprocess_steps_per_second']['median']:.0f} steps/s")
        print(f"in-process / pipeline: {result['ratio_inprocess_over_pipeline']:.1f}x   (target: >= 1000 steps/s)")
    return 0


def bench_command(args) -> int:
    return {"pipeline": bench_pipeline}[args.bench_command](args)
