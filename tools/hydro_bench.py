"""Cost per evaluation of the two hydrodynamic fidelities (`nearsub bench hydro`), and the HF
panel-convergence study written to docs/hydro/."""

from __future__ import annotations

import csv
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from nearsub.common.hydro import high_fidelity as hydro_hf
from nearsub.common.hydro import low_fidelity as hydro_lf
from nearsub.common.surrogate.domain import sample_feasible

# Poses of the convergence study: thesis figure 4-4's UUV (D_sub/D_uuv = 10, L/D = 8) mid-gap over
# the midbody, the bow and the stern, then the smallest clearances (4.4) allows for a small and a
# large UUV. Columns as hydro_lf: [R_long, R_lat, u_kn, psi_deg, d_ratio, ld_ratio].
CONVERGENCE_POSES = {
    "midbody": [0.0, 0.075, 3.5, 0.0, 10.0, 8.0],
    "bow": [0.45, 0.075, 3.5, 0.0, 10.0, 8.0],
    "stern": [-0.4, 0.075, 3.5, 0.0, 10.0, 8.0],
    "small, tight": [-0.3, 0.061, 3.5, 2.0, 40.0, 10.0],
    "large, tight": [0.0, 0.0725, 3.5, 0.0, 5.0, 5.0],
}
REFINEMENTS = (0.5, 0.71, 1.0, 1.41, 2.0)  # factors on MEDIUM's panel counts (and 1/factor on its spacing)


def refined(factor: float, base: hydro_hf.Panels = hydro_hf.MEDIUM) -> hydro_hf.Panels:
    """`base` with every panel count times `factor` and the window spacing over it."""
    return replace(
        base,
        sub_stations=round(base.sub_stations * factor),
        sub_azimuths=max(4, round(base.sub_azimuths * factor)),
        window_spacing=base.window_spacing / factor,
        uuv_stations=round(base.uuv_stations * factor),
        uuv_azimuths=max(4, round(base.uuv_azimuths * factor)),
    )


def benchmark_fidelities(n_lf: int = 1000, n_hf: int = 3, panels: hydro_hf.Panels = hydro_hf.MEDIUM, seed: int = 0):
    """Print and return the cost per point of the low fidelity (one batch of n_lf feasible points)
    and of the high fidelity (n_hf feasible points, one at a time), after the one-off setup of each
    (the LF's submarine field table, the HF's Munk-efficiency calibration)."""
    points = sample_feasible(max(n_lf, n_hf), seed=seed)
    start = time.perf_counter()
    hydro_lf.submarine_field()
    lf_setup = time.perf_counter() - start
    start = time.perf_counter()
    hydro_lf.lf_coefficients(points[:n_lf])
    lf_cost = (time.perf_counter() - start) / n_lf
    start = time.perf_counter()
    hydro_hf.munk_efficiency(panels)
    hf_setup = time.perf_counter() - start
    hf_costs = []
    for row in points[:n_hf]:
        start = time.perf_counter()
        hydro_hf.hf_coefficients(row, panels)
        hf_costs.append(time.perf_counter() - start)
    result = {
        "lf_setup_s": lf_setup,
        "lf_ms_per_point": 1e3 * lf_cost,
        "lf_batch": n_lf,
        "hf_setup_s": hf_setup,
        "hf_s_per_point": float(np.mean(hf_costs)),
        "hf_s_max": float(np.max(hf_costs)),
        "hf_points": n_hf,
    }
    print(
        f"low fidelity:  {result['lf_ms_per_point']:.3f} ms a point (batch of {n_lf}; "
        f"one-off field table {lf_setup:.1f} s)"
    )
    print(
        f"high fidelity: {result['hf_s_per_point']:.2f} s a point (max {result['hf_s_max']:.2f} s over {n_hf}; "
        f"one-off calibration {hf_setup:.2f} s)"
    )
    return result


def panel_convergence(out_dir: str | Path, refinements=REFINEMENTS, poses=None) -> list[dict]:
    """HF [X', Y', N'] at each pose on meshes refined by each factor; writes
    panel-convergence.csv and panel-convergence.png into out_dir and returns the rows."""
    poses = CONVERGENCE_POSES if poses is None else poses
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for factor in refinements:
        panels = refined(factor)
        for name, pose in poses.items():
            start = time.perf_counter()
            x, y, n = hydro_hf.hf_coefficients(pose, panels)[0]
            rows.append(
                {
                    "pose": name,
                    "refinement": factor,
                    **asdict(panels),
                    "unknowns": _unknowns(pose, panels),
                    "X_p": x,
                    "Y_p": y,
                    "N_p": n,
                    "seconds": time.perf_counter() - start,
                    "munk_efficiency": hydro_hf.munk_efficiency(panels),
                }
            )
            print(
                f"{name:14s} x{factor:<5} {rows[-1]['unknowns']:6d} unknowns  X'={x:+.4e} Y'={y:+.4e} N'={n:+.4e}"
                f"  {rows[-1]['seconds']:.1f} s",
                flush=True,
            )
    with open(out_dir / "panel-convergence.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    _plot(rows, out_dir / "panel-convergence.png")
    return rows


def _unknowns(pose, panels: hydro_hf.Panels) -> int:
    """Half-mesh panel count (the size of the dense system) of one pose."""
    x_c, y_c, _, psi, diameter, length = (float(v[0]) for v in hydro_lf.input_columns(pose))
    _, uuv, sub = hydro_hf.two_body_meshes(x_c, y_c, psi, diameter, length, panels)
    return len(sub) + len(uuv)


def _plot(rows: list[dict], path: Path) -> None:
    """Top: X', Y', N' against the panel count; bottom: their distance from the finest mesh's value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, axes = plt.subplots(2, 3, figsize=(13, 7.5), constrained_layout=True)
    for name in dict.fromkeys(r["pose"] for r in rows):
        mine = sorted((r for r in rows if r["pose"] == name), key=lambda r: float(r["unknowns"]))
        count = [float(r["unknowns"]) for r in mine]
        for column, key in enumerate(("X_p", "Y_p", "N_p")):
            value = np.array([float(r[key]) for r in mine])
            axes[0, column].plot(count, value, "o-", label=name)
            axes[1, column].plot(count[:-1], np.abs(value[:-1] / value[-1] - 1.0), "o-", label=name)
    for column, label in enumerate(("X'", "Y'", "N'")):
        for row in (0, 1):
            axes[row, column].set_xscale("log")
            axes[row, column].xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            axes[row, column].set_xlabel("unknowns (half-mesh panels)")
            axes[row, column].grid(True, which="both", alpha=0.3)
        axes[0, column].set_ylabel(label)
        axes[1, column].set_yscale("log")
        axes[1, column].set_ylabel(f"|{label} / {label}(finest) - 1|")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("HF two-way panel model: convergence with panel count (refinement x0.5 ... x2 of MEDIUM)")
    fig.savefig(path, dpi=110)
    plt.close(fig)
