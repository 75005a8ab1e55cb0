"""`nearsub envelope`: safe operating envelopes (thesis sections 5.11 and 6.4) as PNG, CSV and JSON.

    nearsub envelope --vehicle sdv --behaviour nuv_compensation --sea-state 5
    nearsub envelope --vehicle small medium large --sea-state 0 6 --workers 2    # a sweep
    nearsub envelope --compare A.json B.json -o compare.png
    nearsub envelope --redraw A.json -o A.png   # an envelope's PNG again from its JSON
    nearsub envelope --vehicle sdv --cell-mission=-0.3,0.065 -o cell.toml   # replay one cell
    nearsub envelope --thesis-figures [--scheduler tcp://HOST:8786]   # into ./thesis-envelopes
    nearsub envelope --thesis-figures --reuse [DIR]   # draw from DIR (OUT/data), flying only what is missing
    nearsub envelope --vehicle sdv --samples 32 [--sample-seed 0] [--wave-phase random]   # P(outcome)

Every option that describes the conditions takes several values; their combinations make a sweep,
one Dask task per configuration with `--workers N` (a local cluster on loopback) or `--scheduler`
(a running cluster). The computation is `common/envelope.py`; this module parses, draws and writes.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from ..support.arguments import integer, number
from ..support.errors import InputError
from ..support.outputs import output_file, output_folder
from ..support.schedulers import scheduler_address

# numpy, matplotlib, rich and the envelope core are imported when a command runs, so that the
# parser builds at once.
# Outcome colours (OUTCOMES order): safe green, large stray yellow, close call orange, collision
# red, infeasible (starts in the hull) light grey; the traffic-light reading of the thesis figures.
COLOURS = ("#4daf4a", "#ffd92f", "#ff7f00", "#e41a1c", "#d9d9d9")
LABELS = ("safe", "large stray", "close call", "collision", "starts in the hull")
HULL_COLOUR = "#4d4d4d"
THESIS_OUT = Path("thesis-envelopes")  # in the working directory; the shipped set is -o docs/envelopes


def add_parser(sub) -> None:
    p = sub.add_parser(
        "envelope",
        description="Fly one UUV per grid cell for --duration seconds and colour each cell by its outcome "
        "(collision > close call > large stray > safe). Options describing conditions take several values; "
        "their combinations form a sweep.",
    )
    p.add_argument("--vehicle", nargs="+", default=["remus100"], help="remus100|nps_auv_ii|sdv or small|medium|large")
    p.add_argument("--behaviour", nargs="+", default=["waypoints"], metavar="NAME", help="helm behaviours")
    p.add_argument(
        "--d-lead", nargs="+", default=["3"], metavar="D", help="lead distance in UUV lengths (3 or 3L) or metres (4m)"
    )
    p.add_argument("--gamma", nargs="+", type=number(), default=[None], help="N_uv compensation gain (default (6.4))")
    p.add_argument("--sea-state", nargs="+", type=int, default=[0], help="thesis table 5.1 (0 = no waves)")
    p.add_argument("--depth", nargs="+", type=number(), default=[50.0], help="operating depth [m]")
    p.add_argument("--u-sub", nargs="+", type=number(), default=[1.5], help="submarine speed [m/s]")
    p.add_argument("--u-ot", nargs="+", type=number(), default=[0.0], help="overtaking speed [m/s]")
    p.add_argument("--grid", type=grid_size, metavar="NxM", help="cells along R_long x R_lat (default 40x20)")
    p.add_argument("--r-long", type=range_pair, metavar="LO,HI", help="R_long range (default -0.8,0.8)")
    p.add_argument("--r-lat", type=range_pair, metavar="LO,HI", help="R_lat range (default 0.05,0.12)")
    p.add_argument("--duration", type=number(), default=None, help="simulated seconds per cell (default 120)")
    p.add_argument("--dt", type=number(), default=None, help="base step [s] (default 0.1)")
    p.add_argument("--model", default="", help="surrogate model file (default: the shipped model)")
    p.add_argument(
        "-o", "--out", default=None, help="output folder, or FILE.png for one envelope (default: envelopes/)"
    )
    p.add_argument("--compare", nargs=2, metavar=("A.json", "B.json"), help="draw two envelopes side by side")
    p.add_argument(
        "--redraw", metavar="STEM.json", help="draw an envelope's PNG again from its JSON (default ./STEM.png)"
    )
    p.add_argument(
        "--thesis-figures",
        action="store_true",
        help=f"figures 5-10..5-14 and 6-7..6-11 into -o (default ./{THESIS_OUT}; the shipped set: -o docs/envelopes)",
    )
    p.add_argument(
        "--cell-mission",
        type=point,
        metavar="R_LONG,R_LAT",
        help="write the mission file of the cell starting there (to replay it with nearsub launch) and stop",
    )
    p.add_argument("--figure", nargs="+", metavar="N", help="with --thesis-figures: only these (e.g. 5-10 6-7)")
    p.add_argument(
        "--reuse",
        nargs="?",
        const="",
        metavar="DIR",
        help="with --thesis-figures: read the configurations stored in DIR (default OUT/data; the shipped ones: "
        "docs/envelopes/data) instead of flying them (delete a JSON to fly it again)",
    )
    p.add_argument(
        "--scheduler",
        type=scheduler_address,
        metavar="ADDRESS",
        help="run the sweep on this Dask scheduler (tcp://host:8786)",
    )
    p.add_argument(
        "--workers", type=integer(minimum=1), metavar="N", help="run the sweep on a local Dask cluster of N processes"
    )
    p.add_argument("--json", action="store_true", help="print the summaries (fractions) as JSON lines")
    p.add_argument(
        "--samples",
        type=integer(minimum=1),
        metavar="K",
        help="fly every cell under K posterior samples of the surrogate's residual: P(outcome) per cell",
    )
    p.add_argument("--sample-seed", type=int, default=0, metavar="S", help="seed of the samples (default 0)")
    p.add_argument(
        "--wave-phase", default="fixed", metavar="fixed|random", help="with --samples: a random wave phase per sample"
    )
    p.set_defaults(func=envelope_command)


# --------------------------------------------------------------------------------- options
def point(text: str) -> tuple[float, float]:
    """'A,B' -> (A, B), both finite, for argparse."""
    finite = number()
    try:
        a, b = (finite(v) for v in text.split(","))
    except (ValueError, argparse.ArgumentTypeError):
        raise argparse.ArgumentTypeError(f"wants two finite numbers A,B, got {text!r}") from None
    return a, b


def range_pair(text: str) -> tuple[float, float]:
    """'LO,HI' -> (LO, HI), finite with LO < HI, for argparse."""
    try:
        low, high = point(text)
    except argparse.ArgumentTypeError:
        low = high = None
    if low is None or not low < high:
        raise argparse.ArgumentTypeError(f"wants LO,HI, finite with LO < HI, got {text!r}")
    return low, high


def grid_size(text: str) -> tuple[int, int]:
    """'NxM' -> (N, M), each at least 1, for argparse."""
    try:
        n_long, n_lat = (int(v) for v in text.lower().split("x"))
    except ValueError:
        n_long = n_lat = 0
    if n_long < 1 or n_lat < 1:
        raise argparse.ArgumentTypeError(f"wants NxM of whole numbers >= 1 (e.g. 40x20), got {text!r}")
    return n_long, n_lat


def d_lead_lengths(text: str, vehicle: str) -> float:
    """'3' or '3L' -> 3 UUV lengths; '4m' -> 4 m in UUV lengths (the bounds are EnvelopeConfig's)."""
    from nearsub.common.physics.vehicles import get_vehicle

    number_text = text.strip()
    metres = number_text.lower().endswith("m")
    if metres or number_text.upper().endswith("L"):
        number_text = number_text[:-1]
    try:
        value = number()(number_text)
    except argparse.ArgumentTypeError:
        raise InputError(f"--d-lead {text}: wants a finite number of UUV lengths (3, 3L) or metres (4m)") from None
    return value / get_vehicle(vehicle).length if metres else value


def envelope_config(**fields):
    """An EnvelopeConfig whose template mission validates: a bad value is one line naming its
    option (the schemas' own bounds; the mission's for what only a mission checks)."""
    from pydantic import ValidationError

    from nearsub.common.analysis import envelope as env
    from nearsub.common.mission.schema import MissionError

    try:
        config = env.EnvelopeConfig(**fields)
        env.cell_mission(config, 0.0, 0.0)
    except ValidationError as exc:
        item = exc.errors()[0]
        option = "--" + str(item["loc"][0]).replace("_", "-")
        raise InputError(f"{option} {item['input']}: {item['msg']}") from None
    except MissionError as exc:
        raise InputError(str(exc)) from None
    return config


def shared_settings(args) -> dict:
    """Grid, duration, step and model: the same for every configuration of a run."""
    settings = {
        "grid": args.grid,
        "r_long": args.r_long,
        "r_lat": args.r_lat,
        "duration": args.duration,
        "dt": args.dt,
        "model": args.model or None,
    }
    return {k: v for k, v in settings.items() if v is not None}


def configs_from_args(args) -> list:
    """The cartesian product of the condition options (EnvelopeConfig each)."""
    from nearsub.common.mission.schema import BEHAVIOURS
    from nearsub.common.physics.vehicles import get_vehicle

    if unknown := [b for b in args.behaviour if b not in BEHAVIOURS]:
        raise LookupError(f"--behaviour {unknown[0]!r} is not one of {', '.join(BEHAVIOURS)}")
    shared = shared_settings(args)
    configs = []
    for vehicle, behaviour, d_lead, gamma, sea_state, depth, u_sub, u_ot in itertools.product(
        args.vehicle, args.behaviour, args.d_lead, args.gamma, args.sea_state, args.depth, args.u_sub, args.u_ot
    ):
        configs.append(
            envelope_config(
                vehicle=get_vehicle(vehicle).name,
                behaviour=behaviour,
                d_lead=d_lead_lengths(d_lead, vehicle),
                gamma=gamma,
                sea_state=sea_state,
                depth=depth,
                u_sub=u_sub,
                u_ot=u_ot,
                **shared,
            )
        )
    return list(dict.fromkeys(configs))


# --------------------------------------------------------------------------------- drawing
def _edges(centres):
    import numpy as np

    if len(centres) == 1:
        return np.array([centres[0] - 0.005, centres[0] + 0.005])
    mid = 0.5 * (centres[1:] + centres[:-1])
    return np.concatenate([[2 * centres[0] - mid[0]], mid, [2 * centres[-1] - mid[-1]]])


def cell_run(config: dict) -> str:
    """What one cell's run is, in a line for the figures: start state, duration, speed, behaviour."""
    speed = config["u_sub"] + config["u_ot"]
    helm = config["behaviour"].replace("_", " ")
    waves = f", sea state {config['sea_state']}" if config["sea_state"] else ""
    return (
        f"one cell: a {config['vehicle']} starts at the cell's centre, heading 0 (along the submarine) at "
        f"{speed:g} m/s,\nand flies {config['duration']:g} s ({helm}, d_lead {config['d_lead']:g} L) along a "
        f"track-line through its start; the submarine at {config['u_sub']:g} m/s{waves}"
    )


def draw_cells_frame(ax, summary: dict):
    """The frame of an envelope's map in metres at equal aspect: x along the submarine (bow to the
    right), y lateral, from its axis, with the hull to scale (hull.py's SUBOFF profile). Returns
    the cell centres and edges in metres (x, y, x_edges, y_edges)."""
    import numpy as np

    from nearsub.common.physics.hull import L_SUB, submarine_outline

    x, y = np.asarray(summary["r_long"]) * L_SUB, np.asarray(summary["r_lat"]) * L_SUB
    x_edges, y_edges = _edges(x), _edges(y)
    hx, hy = submarine_outline()
    ax.fill(hx, hy, color=HULL_COLOUR, zorder=3)
    ax.set_aspect("equal")
    ax.set_xlim(x_edges[[0, -1]])
    ax.set_ylim(min(0.0, y_edges[0]), y_edges[-1])
    ax.set_xlabel("x along the submarine [m]  (from its centre of buoyancy, bow to the right)")
    ax.set_ylabel("y lateral [m]")
    return x, y, x_edges, y_edges


def draw_envelope(ax, summary: dict, title: str | None = None) -> None:
    """Cells coloured by outcome over the submarine's hull, in metres, with the window where the
    residual GP corrects the LF drawn dashed (the LF acts at every cell)."""
    import numpy as np
    from matplotlib.colors import BoundaryNorm, ListedColormap

    from nearsub.common.analysis.batch import OUTCOMES
    from nearsub.common.analysis.envelope import surrogate_window
    from nearsub.common.physics.hull import L_SUB
    from nearsub.common.surrogate import domain

    _, _, x_edges, y_edges = draw_cells_frame(ax, summary)
    ax.pcolormesh(
        x_edges,
        y_edges,
        np.asarray(summary["outcome"]).T,
        cmap=ListedColormap(COLOURS),
        norm=BoundaryNorm(np.arange(len(OUTCOMES) + 1) - 0.5, len(OUTCOMES)),
        linewidth=0,  # cells can be a few pixels tall: white edges would wash them out
    )
    window = surrogate_window(summary["config"]["vehicle"])
    if window is None:
        note = "the residual GP never corrects the LF on this hull: it fails constraint (4.6) or (4.7)"
        ax.text(
            0.5,
            0.96,
            note,
            transform=ax.transAxes,
            ha="center",
            va="top",
            fontsize=7,
            zorder=5,
            bbox={"facecolor": "white", "edgecolor": "black", "linestyle": "--", "linewidth": 0.8},
        )
    else:
        low, high = (L_SUB * r for r in window)
        x_lo, x_hi = (L_SUB * r for r in domain.BOUNDS[0])
        ax.plot([x_lo, x_hi, x_hi, x_lo, x_lo], [low, low, high, high, low], "k--", linewidth=0.8, zorder=4)
    fractions = summary["fractions"]
    text = ", ".join(f"{LABELS[k]} {100 * fractions[name]:.0f}%" for k, name in enumerate(OUTCOMES[:-1]))
    ax.set_title((title or summary["label"]) + f"\n{text}\n{cell_run(summary['config'])}", fontsize=8)


def legend_handles() -> list:
    from matplotlib.patches import Patch

    handles = [Patch(facecolor=c, edgecolor="grey", label=label) for c, label in zip(COLOURS, LABELS, strict=True)]
    handles.append(Patch(facecolor=HULL_COLOUR, label="submarine (SUBOFF, D = 10.4 m)"))
    handles.append(
        Patch(facecolor="none", edgecolor="black", linestyle="--", label="residual GP trained (table 4.2, 4.4-4.5)")
    )
    return handles


PANEL_WIDTH = 12.0  # [in]: a cell a third of a metre tall stays a few pixels tall at 110 dpi


def _map_aspect(summary: dict) -> float:
    """Height over width of an envelope's map in metres (`draw_cells_frame`'s limits)."""
    import numpy as np

    x, y = _edges(np.asarray(summary["r_long"])), _edges(np.asarray(summary["r_lat"]))
    return (y[-1] - min(0.0, y[0])) / (x[-1] - x[0])


def draw_panels(panels: list[tuple[str, dict]], columns: int, suptitle: str, path: Path) -> Path:
    """Panels (caption, summary) in rows of `columns`, one legend below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = -(-len(panels) // columns)
    legend_height = 0.55  # [in]
    # Equal aspect: a panel is as tall as its map's extent in metres makes it at PANEL_WIDTH, plus
    # its four title lines and the x label.
    spans = [_map_aspect(summary) for _, summary in panels]
    height = sum((PANEL_WIDTH - 0.9) * max(spans[r * columns : (r + 1) * columns]) + 1.7 for r in range(rows))
    height += 0.4 + legend_height
    fig, axes = plt.subplots(rows, columns, figsize=(PANEL_WIDTH * columns, height), squeeze=False)
    for ax, (caption, summary) in zip(axes.ravel(), panels, strict=False):
        draw_envelope(ax, summary, caption)
    for ax in axes.ravel()[len(panels) :]:
        ax.set_visible(False)
    fig.suptitle(suptitle, fontsize=11)
    fig.legend(handles=legend_handles(), loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, legend_height / height, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# --------------------------------------------------------------------------------- writing
def write_cells_csv(envelope, path: Path) -> Path:
    rows = envelope.cell_rows()
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return path


def write_envelope(envelope, stem: Path) -> list[Path]:
    """STEM.png, STEM.csv and STEM.json."""
    from nearsub.common.analysis import envelope as env

    stem.parent.mkdir(parents=True, exist_ok=True)
    summary = envelope.summary()
    return [
        draw_panels([(summary["label"], summary)], 1, "Operating envelope", stem.with_suffix(".png")),
        write_cells_csv(envelope, stem.with_suffix(".csv")),
        env.save_summary(summary, stem.with_suffix(".json")),
    ]


def _progress():
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    return Progress(*columns, console=None, disable=not sys.stderr.isatty(), transient=False)


@contextmanager
def model_errors():
    """A --model file that cannot be read, or that the increment mode has no free-stream table for
    (a model from `train --data`): one line naming it (the errors' texts do), from wherever its
    first cell ran."""
    from nearsub.common.surrogate.interaction import IncrementError
    from nearsub.common.surrogate.modelfile import ModelFileError

    try:
        yield
    except (ModelFileError, IncrementError) as exc:
        raise InputError(str(exc)) from None


def run_configs(configs: list, args) -> list:
    """One envelope in this process with a bar over its steps; several as a sweep with a bar over
    configurations (on Dask with --workers or --scheduler)."""
    from nearsub.common.analysis import envelope as env

    with model_errors(), _progress() as progress:
        if len(configs) == 1 and not (args.workers or args.scheduler):
            n_long, n_lat = configs[0].grid
            task = progress.add_task(f"{n_long * n_lat} cells, steps", total=None)

            def on_step(done: int, total: int) -> None:
                progress.update(task, completed=done, total=total)

            return [env.compute_envelope(configs[0], on_step=on_step)]
        task = progress.add_task("envelopes", total=len(configs))
        return env.sweep(configs, args.scheduler, args.workers, on_done=lambda *_: progress.advance(task))


def fractions_line(summary: dict) -> str:
    f = summary["fractions"]
    return (
        f"{summary['label']}: safe {100 * f['safe']:.1f}%, large stray {100 * f['large_stray']:.1f}%, "
        f"close call {100 * f['close_call']:.1f}%, collision {100 * f['collision']:.1f}% "
        f"({summary['feasible_cells']} feasible cells, {summary['wall_time']:.1f} s)"
    )


def envelope_command(args) -> int:
    if args.compare:
        return compare_command(args)
    if args.redraw:
        return redraw_command(args)
    if args.thesis_figures:
        return thesis_command(args)
    configs = configs_from_args(args)
    if args.cell_mission:
        return cell_mission_command(configs, args)
    if args.samples is not None or args.wave_phase != "fixed":
        return sampled_command(configs, args)
    out, single_file = envelope_output(args, configs)
    started = time.perf_counter()
    envelopes = run_configs(configs, args)
    for envelope in envelopes:
        stem = out.with_suffix("") if single_file else out / envelope.config.slug()
        paths = write_envelope(envelope, stem)
        summary = envelope.summary()
        if args.json:
            print(json.dumps({k: summary[k] for k in ("config", "label", "cells", "counts", "fractions", "wall_time")}))
        else:
            print(fractions_line(summary))
            print("  wrote " + ", ".join(str(p) for p in paths))
    if not args.json and len(envelopes) > 1:
        print(f"{len(envelopes)} envelopes in {time.perf_counter() - started:.1f} s")
    return 0


def envelope_output(args, configs: list) -> tuple[Path, bool]:
    """-o checked before any cell flies: STEM.png|json|csv for one envelope, else a folder."""
    out = Path(args.out or "envelopes")
    if len(configs) == 1 and out.suffix.lower() in (".png", ".json", ".csv"):
        return output_file(out, parents=True), True
    return output_folder(out), False


def cell_mission_command(configs: list, args) -> int:
    """One TOML mission per configuration: the cell whose UUV starts at (R_long, R_lat)."""
    from nearsub.common.analysis import envelope as env
    from nearsub.common.physics.hull import L_SUB

    r_long, r_lat = args.cell_mission
    out = Path(args.out or "envelopes")
    single_file = out.suffix == ".toml" and len(configs) == 1
    output_file(out, parents=True) if single_file else output_folder(out)
    for config in configs:
        path = out if single_file else out / f"{config.slug()}_cell.toml"
        path.parent.mkdir(parents=True, exist_ok=True)
        data = env.mission_data(config, r_long * L_SUB, r_lat * L_SUB, name="envelope_cell")
        path.write_text(env.mission_toml(data))
        print(f"wrote {path}   (nearsub launch {path})")
    return 0


def compare_command(args) -> int:
    from nearsub.common.analysis import envelope as env

    try:
        first, second = (env.load_summary(path) for path in args.compare)
    except (OSError, ValueError) as exc:
        print(f"nearsub envelope --compare: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out or "envelope-compare.png")
    if out.suffix.lower() != ".png":
        out = out / "compare.png"
    output_file(out, parents=True).parent.mkdir(parents=True, exist_ok=True)
    draw_panels([(first["label"], first), (second["label"], second)], 2, "Operating envelopes compared", out)
    print(fractions_line(first))
    print(fractions_line(second))
    print(f"wrote {out}")
    return 0


def redraw_command(args) -> int:
    """The PNG of a stored envelope, plain or sampled (P(collision)), drawn from its JSON alone."""
    source = Path(args.redraw)
    try:
        summary = json.loads(source.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"--redraw {source}: {exc}") from None
    if "config" not in summary or not ({"outcome", "probability"} & set(summary)):
        raise InputError(f"--redraw {source}: not an envelope summary (no config, outcome or probability grid)")
    out = output_file(Path(args.out or source.with_suffix(".png").name), source=source, parents=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    if "probability" in summary:
        draw_collision_probability(summary, out)
    else:
        draw_panels([(summary["label"], summary)], 1, "Operating envelope", out)
    print(f"wrote {out}")
    return 0


# --------------------------------------------------------------------------------- sampled envelopes
def draw_collision_probability(summary: dict, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig = collision_probability_figure(summary)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def collision_probability_figure(summary: dict):
    """P(collision) per cell over the submarine's hull in metres, with contours, the cells marked
    safe (P(collision) < safe_below) dotted and infeasible cells grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.colors import ListedColormap
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    p = summary["probability"]
    collision = np.asarray(p["collision"], dtype=float)
    infeasible = np.asarray(p["infeasible"]) == 1.0
    fig, ax = plt.subplots(figsize=(PANEL_WIDTH, (PANEL_WIDTH - 2.0) * _map_aspect(summary) + 2.4))
    x, y, x_edges, y_edges = draw_cells_frame(ax, summary)
    mesh = ax.pcolormesh(
        x_edges,
        y_edges,
        np.ma.masked_where(infeasible, collision).T,
        cmap="Reds",
        vmin=0.0,
        vmax=1.0,
        linewidth=0,
    )
    grey = ListedColormap([COLOURS[-1]])
    ax.pcolormesh(x_edges, y_edges, np.ma.masked_where(~infeasible, collision).T, cmap=grey)
    if len(x) > 1 and len(y) > 1:
        lines = ax.contour(x, y, collision.T, levels=[0.05, 0.5, 0.95], colors="black", linewidths=0.8)
        ax.clabel(lines, fmt=lambda v: f"{100 * v:.0f}%", fontsize=7)
    safe = np.asarray(summary["marked_safe"], dtype=bool)
    i, j = np.nonzero(safe)
    ax.plot(x[i], y[j], "o", color="#1a9850", markersize=2.5, zorder=4)
    fig.colorbar(mesh, ax=ax, label="P(collision)", shrink=0.6)
    sampling = summary["sampling"]
    waves = ", random wave phase" if sampling["wave_phase"] == "random" else ""
    f = summary["expected_fractions"]
    ax.set_title(
        f"{summary['label']}\nK = {sampling['samples']} posterior samples{waves}; expected collision "
        f"{100 * f['collision']:.1f}%, close call {100 * f['close_call']:.1f}%; "
        f"{int(safe.sum())} of {summary['feasible_cells']} cells P(collision) < {100 * summary['safe_below']:g}%"
        f"\n{cell_run(summary['config'])}",
        fontsize=8,
    )
    handles = [
        Line2D([], [], marker="o", linestyle="", color="#1a9850", markersize=4, label="P(collision) < 1 %"),
        Line2D([], [], color="black", linewidth=0.8, label="P(collision) contours 5, 50, 95 %"),
        Patch(facecolor=HULL_COLOUR, label="submarine"),
        Patch(facecolor=COLOURS[-1], label=LABELS[-1]),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    return fig


def sampled_command(configs: list, args) -> int:
    """One uncertainty-aware envelope per configuration: STEM.png (P(collision)), STEM.csv and
    STEM.json (per cell: P(outcome), closest-approach quantiles)."""
    from nearsub.common.analysis import envelope as env

    if args.samples is None:
        raise LookupError("--wave-phase random needs --samples K")
    try:
        sampling = env.Sampling(args.samples, args.sample_seed, args.wave_phase)
    except ValueError as exc:
        raise LookupError(str(exc)) from None
    out, single_file = envelope_output(args, configs)
    for config in configs:
        with model_errors(), _progress() as progress:
            task = progress.add_task(f"{sampling.samples} x {config.grid[0] * config.grid[1]} cells, steps", total=None)
            envelope = env.sampled_envelope(
                config,
                sampling,
                args.scheduler,
                args.workers,
                on_step=lambda done, total, task=task: progress.update(task, completed=done, total=total),
            )
        stem = out.with_suffix("") if single_file else out / f"{config.slug()}_samples{sampling.samples}"
        stem.parent.mkdir(parents=True, exist_ok=True)
        summary = envelope.summary()
        paths = [
            draw_collision_probability(summary, stem.with_suffix(".png")),
            write_cells_csv(envelope, stem.with_suffix(".csv")),
            env.save_summary(summary, stem.with_suffix(".json")),
        ]
        f = summary["expected_fractions"]
        if args.json:
            print(
                json.dumps({k: summary[k] for k in ("config", "label", "sampling", "expected_fractions", "wall_time")})
            )
        else:
            print(
                f"{summary['label']}, K = {sampling.samples}: expected safe {100 * f['safe']:.1f}%, large stray "
                f"{100 * f['large_stray']:.1f}%, close call {100 * f['close_call']:.1f}%, collision "
                f"{100 * f['collision']:.1f}%; {sum(map(sum, summary['marked_safe']))} cells P(collision) < 1% "
                f"({summary['feasible_cells']} feasible cells, {summary['wall_time']:.1f} s)"
            )
            print("  wrote " + ", ".join(str(p) for p in paths))
    return 0


# --------------------------------------------------------------------------------- thesis figures
def thesis_command(args) -> int:
    """Every envelope figure of chapters 5 and 6: one JSON per configuration in OUT/data, one PNG
    per figure, and the fractions table (fractions.md, fractions.csv)."""
    from nearsub.common.analysis import envelope as env

    out = output_folder(args.out or THESIS_OUT)
    overrides = shared_settings(args)
    envelope_config(**overrides)  # a bad --grid, --duration, ... before anything is written
    figures = env.thesis_figures()
    unknown = set(args.figure or ()) - {f.number for f in figures}
    if unknown:
        known = ", ".join(f.number for f in figures)
        print(f"nearsub envelope: no thesis figure {', '.join(sorted(unknown))} (known: {known})", file=sys.stderr)
        return 2
    figures = [f for f in figures if not args.figure or f.number in args.figure]
    configs = env.unique_configs(figures, **overrides)
    reuse = None if args.reuse is None else Path(args.reuse or out / "data")
    if args.reuse and not reuse.is_dir():
        raise InputError(f"--reuse {reuse}: no such folder")
    summaries = stored_summaries(configs, reuse) if reuse is not None else {}
    flown = [config for config in configs if config not in summaries]
    started = time.perf_counter()
    envelopes = run_configs(flown, args) if flown else []
    total = time.perf_counter() - started
    data = out / "data"
    data.mkdir(parents=True, exist_ok=True)
    # OUT/data gets what was flown, and a copy of what was read elsewhere, for the next --reuse
    copied = [] if reuse is None or reuse.resolve() == data.resolve() else list(summaries.items())
    for envelope in envelopes:
        summaries[envelope.config] = envelope.summary()
    for config, summary in copied + [(e.config, summaries[e.config]) for e in envelopes]:
        env.save_summary(summary, data / f"{config.slug()}.json")
    rows = []
    for figure in figures:
        panels = []
        for caption, config in figure.panels:
            summary = summaries[config.model_copy(update=overrides) if overrides else config]
            panels.append((caption, summary))
            rows.append((figure.number, caption, summary))
        path = draw_panels(
            panels, figure.columns, f"Figure {figure.number}: {figure.title}", out / f"figure-{figure.number}.png"
        )
        print(f"wrote {path}")
    write_fractions(rows, out, [f.number for f in env.thesis_figures()])
    steps = sum(s["vehicle_steps"] for s in (e.summary() for e in envelopes))
    timing = {
        "configurations": len(flown),
        "reused": len(configs) - len(flown),
        "wall_time": round(total, 1),
        "vehicle_steps": steps,
        "vehicle_steps_per_second": round(steps / total) if flown else 0,
        "scheduler": args.scheduler or (f"local cluster, {args.workers} workers" if args.workers else "this process"),
    }
    (out / "timing.json").write_text(json.dumps(timing, indent=1) + "\n")
    reused = f", {timing['reused']} read from {reuse}" if timing["reused"] else ""
    print(f"{len(flown)} envelopes in {total:.1f} s ({timing['vehicle_steps_per_second']} vehicle-steps/s){reused}")
    return 0


def stored_summaries(configs: list, folder: Path) -> dict:
    """The summaries in `folder` (SLUG.json) whose configuration is one of `configs`."""
    from nearsub.common.analysis import envelope as env

    found = {}
    for config in configs:
        path = folder / f"{config.slug()}.json"
        if path.exists():
            summary = env.load_summary(path)
            if env.EnvelopeConfig(**summary["config"]) == config:
                found[config] = summary
    return found


def write_fractions(rows: list[tuple[str, str, dict]], out: Path, order: list[str]) -> None:
    """The safe / stray / close-call / collision fractions of every panel, as CSV and Markdown. The
    rows of figures this run did not draw stay as the files had them, so a `--figure` run into a
    full set replaces its own rows only; figures in `order`."""
    from nearsub.common.analysis import envelope as env
    from nearsub.common.analysis.batch import OUTCOMES

    names = OUTCOMES[:-1]
    drawn = {number for number, _, _ in rows}
    csv_header = ["figure", "panel", "configuration", *names, "feasible_cells"]
    csv_rows = [
        [number, caption, env.EnvelopeConfig(**s["config"]).slug(), *(f"{s['fractions'][n]:.3f}" for n in names)]
        + [s["feasible_cells"]]
        for number, caption, s in rows
    ]
    md_header = ["| figure | panel | safe | large stray | close call | collision |", "|---|---|---:|---:|---:|---:|"]
    md_rows = [
        f"| {number} | {caption} | " + " | ".join(f"{100 * s['fractions'][n]:.0f}%" for n in names) + " |"
        for number, caption, s in rows
    ]
    csv_path, md_path = out / "fractions.csv", out / "fractions.md"
    if csv_path.exists():
        with csv_path.open(newline="") as handle:
            csv_rows += [row for row in list(csv.reader(handle))[1:] if row and row[0] not in drawn]
    if md_path.exists():
        kept = md_path.read_text().splitlines()[len(md_header) :]
        md_rows += [line for line in kept if line.split("|")[1].strip() not in drawn]

    def figure_order(number: str) -> int:
        return order.index(number) if number in order else len(order)

    csv_rows.sort(key=lambda row: figure_order(row[0]))  # stable: a figure's panels keep their order
    md_rows.sort(key=lambda line: figure_order(line.split("|")[1].strip()))
    with csv_path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(csv_header)
        writer.writerows(csv_rows)
    md_path.write_text("\n".join(md_header + md_rows) + "\n")
