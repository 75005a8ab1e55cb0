"""`python -m nearsub.tools.fleet_figure MISSION [-o PNG]`: a mission of several vehicles flown
in-process (the launched run equals it bit for bit, tests/test_fleet_pipeline.py), drawn as every
vehicle's track in the submarine frame with the hull, the waypoints and the encounters, and each
vehicle's clearance from the hull over time; prints the figures of merit
(`common/analysis/fleet.py`) that docs/scenarios/launch_two.md quotes. Writes to `-o` (default
./MISSION.png), never over the docs unless told."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m nearsub.tools.fleet_figure", description=__doc__)
    parser.add_argument("mission", help="a mission file with [[vehicles]]")
    parser.add_argument("-o", "--output", help="PNG to write (default: ./<mission name>.png)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a mission setting")
    args = parser.parse_args(argv)
    from nearsub.common.mission.schema import MissionError, load_mission

    try:
        mission = load_mission(args.mission, args.set)
    except MissionError as exc:
        print(f"fleet_figure: {exc}", file=sys.stderr)
        return 2
    if not mission.fleet:
        print(f"fleet_figure: {args.mission}: the mission has no [[vehicles]]", file=sys.stderr)
        return 2
    from nearsub.common.analysis.fleet import fleet_figures
    from nearsub.common.mission.cores import run_mission

    figures = fleet_figures(mission, run_mission(mission))
    output = Path(args.output or f"{mission.name}.png")
    draw(mission, figures, output)
    print(report(figures))
    print(f"wrote {output}")
    return 0


def report(figures) -> str:
    lines = [f"outcome {figures.outcome} after {figures.duration:.2f} s ({figures.reason})"]
    for v in figures.vehicles:
        phases = ", ".join(f"{phase} at {t:.2f} s" for phase, t in v.phase_times.items()) or "no PHASE posted"
        done = "not completed" if v.completed_at is None else f"completed at {v.completed_at:.2f} s"
        lines.append(f"  {v.name} ({v.type}): {phases}; {done}; closest to the hull {v.closest_hull:.2f} m")
    for (a, b), (gap, t) in figures.closest_pair.items():
        lines.append(f"  {a} - {b}: closest {gap:.2f} m apart at t = {t:.2f} s")
    lines += [f"  {text}" for text in figures.encounter_events] or ["  no encounter between the vehicles"]
    return "\n".join(lines)


def draw(mission, figures, output: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from nearsub.common.physics.hull import submarine_outline, uuv_outline

    fig, (plan, clear) = plt.subplots(2, 1, figsize=(9, 9), gridspec_kw={"height_ratios": [3, 1.3]})
    if mission.environment.submarine:
        sx, sy = submarine_outline()
        plan.fill(sx, sy, color="0.8", edgecolor="0.3", label="submarine")
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for colour, v in zip(colours, figures.vehicles, strict=False):
        member = mission.member(v.name)
        model = member.vehicle_model
        x, y, psi = v.track.T
        plan.plot(x, y, color=colour, lw=1.2, label=f"{v.name} ({v.type})")
        for k in (0, len(x) - 1):
            ox, oy = uuv_outline(x[k], y[k], psi[k], model.length, model.diameter)
            plan.fill(ox, oy, color=colour)
        for spec in member.apps.helm.behaviour_specs():
            for leg in getattr(spec, "legs", []):
                px, py = zip(*leg.points, strict=True)
                plan.plot(px, py, "*", color=colour, ms=10)
        for phase, t in v.phase_times.items():
            k = min(int(round(t / mission.dt)), len(x) - 1)
            plan.annotate(phase, (x[k], y[k]), textcoords="offset points", xytext=(4, 4), fontsize=8, color=colour)
        clear.plot(v.times, v.hull_clearance, color=colour, label=v.name)
    plan.set_aspect("equal")
    plan.set_xlabel("x [m] (submarine frame, bow +x)")
    plan.set_ylabel("y [m]")
    plan.set_title(f"{mission.name}: U_sub = {mission.environment.u_sub:g} m/s; {figures.outcome}")
    plan.legend(loc="upper right", fontsize=8)
    plan.set_xlim(-60, 60)
    top = max(float(v.track[:, 1].max()) for v in figures.vehicles)
    plan.set_ylim(-12, max(45.0, top + 5.0))  # room above the farthest departure point and its label
    clear.set_xlabel("t [s]")
    clear.set_ylabel("clearance from hull [m]")
    clear.set_yscale("log")
    clear.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(output, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
