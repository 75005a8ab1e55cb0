"""`nearsub maps [MODEL] [--out DIR]`: the colour maps of thesis section 4.5 as PNGs.

One PNG per thesis figure (4-4, 4-5, 4-7, 4-8, 4-9, 4-10, 4-11), panels as in the thesis, from
the slices of `common/surrogate_maps.py`. Each panel shows the model's training points projected
onto its two inputs as dots, grey where constraints (4.4)-(4.7) exclude the slice, and a zero
contour. A strip under each figure draws the submarine outline to scale with the UUV at the
slice's held position; maps over R_long and R_lat also draw the hull's edge in the map.
Figures 4-9 to 4-11 compare the model with its low-fidelity GP, so they need a multi-fidelity
model file; for a single-fidelity one they are skipped.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from nearsub.common.surrogate.maps import LABELS, MID_WINDOW, THESIS_MAPS, MapPanel, mid_window_r_lat

DEFAULT_OUT = Path("docs") / "maps"
_FIDELITY_TITLES = {"hf": "HF-trained surrogate", "lf": "LF surrogate"}


def _held_text(panel: MapPanel) -> str:
    """The held inputs, in the caption style of the thesis."""
    parts = []
    for name, value in panel.held.items():
        if name in (panel.x, panel.y):
            continue
        if value == MID_WINDOW:
            if {"d_ratio", "ld_ratio"} & {panel.x, panel.y}:
                parts.append("R_lat mid-window (thesis 0.08)")
            else:
                r_lat = float(mid_window_r_lat(panel.held["d_ratio"], panel.held["ld_ratio"]))
                parts.append(f"R_lat = {r_lat:.4f} (mid-window; thesis 0.08)")
        else:
            parts.append(f"{LABELS[name]} = {value:g}")
    return ", ".join(parts)


def _draw_hull_edge(ax, x_range) -> None:
    """The submarine's side (|y| <= r) in R_long, R_lat coordinates, filled."""
    from nearsub.common.physics.hull import L_SUB, submarine_half_width

    x = np.linspace(*x_range, 600)
    ax.fill_between(x, 0.0, submarine_half_width(x * L_SUB) / L_SUB, color="0.35", zorder=3, lw=0)


def _draw_position_strip(ax, panels: tuple[MapPanel, ...]) -> None:
    """Plan view to scale: the submarine, the map's window in R_long/R_lat, and the reference UUV."""
    from matplotlib.patches import Rectangle

    from nearsub.common.physics.hull import L_SUB, submarine_outline, uuv_dimensions, uuv_outline

    sx, sy = submarine_outline()
    ax.fill(sx / L_SUB, sy / L_SUB, color="0.35", lw=0)
    panel = panels[0]
    held = panel.held
    d_ratio = held["d_ratio"] if "d_ratio" not in (panel.x, panel.y) else 20.0
    ld_ratio = held["ld_ratio"] if "ld_ratio" not in (panel.x, panel.y) else 8.0
    diameter, length = (float(v) for v in uuv_dimensions(d_ratio, ld_ratio))
    if {panel.x, panel.y} == {"R_long", "R_lat"}:
        ax.add_patch(Rectangle((-0.7, 0.059), 1.4, 0.046, fill=False, ec="C3", lw=1.0, label="map window"))
        r_long, r_lat = 0.0, float(mid_window_r_lat(d_ratio, ld_ratio))
        label = f"UUV, D_sub/D_uuv = {d_ratio:g}, L/D = {ld_ratio:g} (size only)"
    else:
        r_lat = float(mid_window_r_lat(d_ratio, ld_ratio))
        r_long = held["R_long"] if panel.x != "R_long" else 0.0
        label = f"UUV at the held position (D_sub/D_uuv = {d_ratio:g}, L/D = {ld_ratio:g})"
        if panel.x == "R_long":
            ax.plot([-0.7, 0.7], [r_lat, r_lat], color="C3", lw=1.0, label="slice (R_long varies)")
    ux, uy = uuv_outline(r_long * L_SUB, r_lat * L_SUB, 0.0, length, diameter)
    ax.fill(ux / L_SUB, uy / L_SUB, color="C1", lw=0, label=label)
    ax.set_aspect("equal")
    ax.set_xlim(-0.75, 0.75)
    ax.set_ylim(-0.07, 0.115)
    ax.set_xlabel("R_long (plan view to scale)")
    ax.set_ylabel("R_lat")
    ax.legend(loc="lower left", fontsize=7, frameon=False, ncol=2)


def _norm(values: np.ndarray):
    """Diverging and symmetric about zero when the values change sign (so white is zero and a tiny
    value stays pale), otherwise sequential."""
    from matplotlib.colors import Normalize

    low, high = float(np.nanmin(values)), float(np.nanmax(values))
    if low < 0.0 < high:
        return Normalize(-max(-low, high), max(-low, high)), "RdBu_r"
    return Normalize(low, high), "viridis"


def plot_figure(surrogate, name: str, out_dir: Path, nx: int = 121, ny: int = 81) -> Path:
    """Draw one thesis figure of `THESIS_MAPS` for a loaded Surrogate; returns the PNG path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from nearsub.common.surrogate.maps import evaluate_map, training_points

    panels = THESIS_MAPS[name]
    maps = [evaluate_map(surrogate.model, panel, nx, ny) for panel in panels]
    # Panels of one output share their colour scale, so HF and LF compare by colour.
    shared = {
        output: np.concatenate([m["values"].ravel() for p, m in zip(panels, maps, strict=True) if p.output == output])
        for output in {p.output for p in panels}
    }
    columns = 2
    rows = (len(panels) + 1) // columns
    fig = plt.figure(figsize=(6.2 * columns, 4.3 * rows + 2.0), constrained_layout=True)
    grid = fig.add_gridspec(rows + 1, columns, height_ratios=[*([4.3] * rows), 1.8])
    for k, (panel, data) in enumerate(zip(panels, maps, strict=True)):
        ax = fig.add_subplot(grid[k // columns, k % columns])
        ax.set_facecolor("0.85")  # grey shows through where the constraints exclude the slice
        norm, cmap = _norm(shared[panel.output])
        mesh = ax.pcolormesh(data["x"], data["y"], data["values"], norm=norm, cmap=cmap, shading="auto")
        if np.nanmin(data["values"]) < 0.0 < np.nanmax(data["values"]):
            ax.contour(data["x"], data["y"], data["values"], levels=[0.0], colors="k", linewidths=0.8)
        fig.colorbar(mesh, ax=ax, label=LABELS[panel.output], format="%.1e")
        points = training_points(surrogate.model, panel.fidelity)
        columns_of = {n: i for i, n in enumerate(("R_long", "R_lat", "u_kn", "psi_deg", "d_ratio", "ld_ratio"))}
        ax.scatter(
            points[:, columns_of[panel.x]],
            points[:, columns_of[panel.y]],
            s=7,
            c="k" if panel.fidelity == "hf" else "none",
            edgecolors="k",
            linewidths=0.6,
            zorder=4,
            label=f"{panel.fidelity.upper()} training points (projected)",
        )
        if {panel.x, panel.y} == {"R_long", "R_lat"}:
            _draw_hull_edge(ax, (data["x"][0], data["x"][-1]))
            ax.set_ylim(0.045, data["y"][-1])
        ax.set_xlim(data["x"][0], data["x"][-1])
        ax.set_xlabel(LABELS[panel.x])
        ax.set_ylabel(LABELS[panel.y])
        ax.set_title(
            f"({panel.panel}) {LABELS[panel.output]}, {_FIDELITY_TITLES[panel.fidelity]}\n{_held_text(panel)}",
            fontsize=9,
        )
        ax.legend(loc="upper right", fontsize=7, framealpha=0.7)
    _draw_position_strip(fig.add_subplot(grid[rows, :]), panels)
    fig.suptitle(
        f"Thesis figure {name.removeprefix('fig')}, nearsub surrogate {surrogate.model_id} "
        "(trained on nearsub's panel-method physics, not CFD)",
        fontsize=11,
    )
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{name}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def maps_command(args) -> int:
    from nearsub.common.surrogate.maps import has_low_fidelity
    from nearsub.common.surrogate.model import load_surrogate
    from nearsub.common.surrogate.modelfile import ModelFileError

    try:
        surrogate = load_surrogate(args.model)
    except ModelFileError as exc:
        print(f"nearsub maps: {exc}", file=sys.stderr)
        return 2
    multi_fidelity = has_low_fidelity(surrogate.model)
    out_dir = Path(args.out)
    for name, panels in THESIS_MAPS.items():
        if not multi_fidelity and any(p.fidelity == "lf" for p in panels):
            print(f"skipped {name}: it compares with the low-fidelity surrogate, and {surrogate.source} has none")
            continue
        print(f"wrote {plot_figure(surrogate, name, out_dir)}")
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("maps", help="colour maps of thesis figures 4-4 to 4-11 as PNGs")
    p.add_argument("model", nargs="?", help="model file (default: the shipped model)")
    p.add_argument("--out", default=str(DEFAULT_OUT), help=f"folder for the PNGs (default {DEFAULT_OUT})")
    p.set_defaults(func=maps_command)
