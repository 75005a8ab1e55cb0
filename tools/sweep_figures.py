"""Figures of `nearsub surrogate sweep`: the interaction increment along heading and lateral
sweeps, HF and LF physics against what the sim applies (docs/hydro/sweeps/)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from nearsub.common.surrogate.domain import BOUNDS  # noqa: E402

SWEEPS = {"heading": ("psi_deg", "heading psi [deg]"), "lateral": ("R_lat", "R_lat = |y| / L_sub")}
SERIES = (("hf", "HF physics", "k.-"), ("lf", "LF physics", "b--"), ("applied", "applied by the sim", "r-"))


def draw_sweeps(rows: list[dict], out_dir: Path, window: tuple[float, float] | None = None) -> list[Path]:
    """One PNG per sweep kind: X', Y', N' increments (rows) at each station (columns). `window` is
    the lateral band of (4.4)-(4.5) for the stations' hull, shaded on the lateral sweep."""
    stations = list(dict.fromkeys(r["station"] for r in rows))
    written = []
    for kind, (column, label) in SWEEPS.items():
        fig, axes = plt.subplots(3, len(stations), figsize=(4.2 * len(stations), 8.0), sharex=True, squeeze=False)
        for j, station in enumerate(stations):
            chosen = [r for r in rows if r["station"] == station and r["sweep"] == kind]
            x = [r[column] for r in chosen]
            for i, output in enumerate(("X_p", "Y_p", "N_p")):
                ax = axes[i, j]
                for source, name, style in SERIES:
                    ax.plot(x, [r[f"{source}_{output}"] for r in chosen], style, label=name, lw=1.2, ms=3)
                if kind == "heading":
                    ax.axvspan(*BOUNDS[3], color="0.88", zorder=0, label="trained heading range")
                elif window is not None:
                    ax.axvspan(*window, color="0.88", zorder=0, label="trained lateral band")
                ax.set_ylabel(f"{output.replace('_p', chr(39))} increment")
                ax.grid(alpha=0.3)
                if i == 0:
                    ax.set_title(f"{station}, R_long = {chosen[0]['R_long']:+.2f}")
            axes[-1, j].set_xlabel(label)
        axes[0, 0].legend(fontsize=7, loc="best")
        fig.suptitle(f"Interaction increment along a {kind} sweep (SDV hull, 3 kn)")
        fig.tight_layout()
        path = out_dir / f"{kind}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        written.append(path)
    return written
