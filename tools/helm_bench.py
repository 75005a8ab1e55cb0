"""`nearsub bench helm`: the cost of the helm's arbitration per decision, and of a whole helm
iteration (behaviours included) of the recovery mission (docs/design.md, "The helm")."""

from __future__ import annotations

import json
import time
from pathlib import Path

from .support.arguments import integer

RECOVERY = Path(__file__).resolve().parents[1] / "missions" / "recovery.toml"


def add_bench_parser(bench_subparsers) -> None:
    t = bench_subparsers.add_parser("helm", help="arbitration cost per decision, and a helm iteration's")
    t.add_argument("--repeats", type=integer(minimum=1), default=2000, help="decisions timed per case")
    t.add_argument("--json", action="store_true")
    t.set_defaults(func=bench_helm)


def _per_call(function, repeats: int) -> tuple[float, float]:
    """Median and least wall seconds of one call, over `repeats` calls in batches of 10 (on a
    shared machine the least is the closest to the cost itself)."""
    import statistics

    samples = []
    for _ in range(max(repeats // 10, 1)):
        start = time.perf_counter()
        for _ in range(10):
            function()
        samples.append((time.perf_counter() - start) / 10)
    return statistics.median(samples), min(samples)


def bench_helm(args) -> int:
    import math
    import os

    import numpy as np

    from nearsub.common.autonomy import helm, ivp
    from nearsub.common.mission.schema import load_mission

    mission = load_mission(RECOVERY)
    vehicle = mission.vehicle_model
    top = helm.top_speed(vehicle)
    hold = np.array([1.5, 0.0, 0.0, -3.44, 6.5, 0.0])  # on the recovery's station point
    situation = helm.Situation(hold, 0.0, {}, vehicle, 1.5)
    avoid = next(s for s in mission.apps.helm.behaviours if s.type == "hull_avoidance")
    table = helm.hull_avoidance(avoid, situation, {}).objective
    two = [(300.0, table), (100.0, ivp.peak_objective(0.01, 1.52))]
    five = [
        *two,
        (100.0, ivp.peak_objective(0.3, 1.2)),
        (50.0, ivp.Objective((0.0, 1.0), heading=ivp.Zaic(math.radians(20.0), 0.0, math.pi, circular=True))),
        (50.0, ivp.Objective((0.0, 1.0), speed=ivp.Zaic(1.0, 0.0, 1.0))),
    ]
    cases = {
        "arbitration, 2 objectives (station keeping + hull avoidance table)": lambda: ivp.arbitrate(two, top),
        "arbitration, 5 objectives (1 table, 4 ZAIC pairs)": lambda: ivp.arbitrate(five, top),
    }
    specs = mission.apps.helm.behaviour_specs()
    rules = tuple(rule.rule() for rule in mission.apps.helm.modes)
    full = helm.Helm(specs, {**mission.apps.helm.variables, "PHASE": "hold"}, rules, vehicle, 1.5)
    cases["helm iteration of the recovery hold (behaviours + arbitration)"] = lambda: full.iterate(hold, 0.0)
    headings, speeds = ivp.decision_grid(top)
    results = {}
    for name, function in cases.items():
        function()  # warm the caches (decision grid, hull distance grids)
        repeats = args.repeats if "arbitration" in name else max(args.repeats // 20, 10)
        median, least = _per_call(function, repeats)
        results[name] = {"median_ms": median * 1e3, "least_ms": least * 1e3}
    load = os.getloadavg()[0]
    if args.json:
        print(json.dumps({"per_call": results, "grid": [len(headings), len(speeds)], "load_average": load}))
        return 0
    print(f"decision grid {len(headings)} headings x {len(speeds)} speeds (0..{top:.2f} m/s); load average {load:.1f}")
    print("  median     least   per call")
    for name, ms in results.items():
        print(f"{ms['median_ms']:8.3f} {ms['least_ms']:8.3f} ms  {name}")
    return 0
