"""Two-dimensional slices of the surrogate: the colour maps of thesis section 4.5 as data.

The surrogate has six inputs; the thesis shows it as maps over two of them with the other four
held (figures 4-4, 4-5, 4-7 to 4-11). `THESIS_MAPS` lists those panels with the thesis's fixed
values, `slice_grid` makes the inputs of a panel and `evaluate_map` the values, NaN where the
constraints (4.4)-(4.7) exclude the point. Plotting is in tools/map_figures.py (`nearsub maps`).

One departure, forced by docs/design.md, "Thesis errata": nearsub's R_lat is centre to centre, so the thesis's
R_lat = 0.08 violates (4.5) (the UUV more than two of its diameters off the hull) for every
D_sub/D_uuv above 10.7, which includes the thesis's D_sub/D_uuv = 20 slices. Where the thesis
holds R_lat at 0.08, these maps put the UUV in the middle of the lateral window that (4.4) and
(4.5) allow for its size (`mid_window_r_lat`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nearsub.common.surrogate.domain import BOUNDS, INPUT_NAMES, constraints_ok
from nearsub.common.surrogate.modelfile import LFInLoopModel

LABELS = {
    "R_long": "R_long",
    "R_lat": "R_lat",
    "u_kn": "u [kn]",
    "psi_deg": "psi [deg]",
    "d_ratio": "D_sub/D_uuv",
    "ld_ratio": "L/D_uuv",
    "X_p": "X'",
    "Y_p": "Y'",
    "N_p": "N'",
}
MID_WINDOW = "mid-window"  # marker for R_lat held in the middle of its allowed window

# The thesis's held values: u = 3.5 kn, psi = 0, R_long = 0, R_lat = 0.08, D_sub/D_uuv = 20 (10 in
# figure 4-4), L/D_uuv = 8 (figure captions 4-4 to 4-11).
_HELD = {"R_long": 0.0, "R_lat": MID_WINDOW, "u_kn": 3.5, "psi_deg": 0.0, "d_ratio": 20.0, "ld_ratio": 8.0}


@dataclass(frozen=True)
class MapPanel:
    """One panel: `output` of the `fidelity` surrogate ('hf': the model; 'lf': its low-fidelity GP)
    over inputs x (horizontal) and y (vertical), the other four held at `held`."""

    figure: str
    panel: str
    output: str
    x: str
    y: str
    fidelity: str = "hf"
    held: dict[str, Any] = field(default_factory=lambda: dict(_HELD))

    @property
    def name(self) -> str:
        return f"{self.figure}{self.panel}"


def _panel(figure: str, panel: str, output: str, x: str, y: str, fidelity: str = "hf", **held) -> MapPanel:
    return MapPanel(figure, panel, output, x, y, fidelity, {**_HELD, **held})


# Figures and captions of thesis section 4.5, panel by panel.
THESIS_MAPS: dict[str, tuple[MapPanel, ...]] = {
    "fig4-4": (  # Y', N' around the submarine, D_sub/D_uuv = 10
        _panel("fig4-4", "a", "Y_p", "R_long", "R_lat", d_ratio=10.0),
        _panel("fig4-4", "b", "N_p", "R_long", "R_lat", d_ratio=10.0),
    ),
    "fig4-5": (  # X' along the submarine: (a) around it, (b) against UUV size
        _panel("fig4-5", "a", "X_p", "R_long", "R_lat"),
        _panel("fig4-5", "b", "X_p", "R_long", "d_ratio"),
    ),
    "fig4-7": (  # Y', N' against heading and speed
        _panel("fig4-7", "a", "Y_p", "psi_deg", "u_kn"),
        _panel("fig4-7", "b", "N_p", "psi_deg", "u_kn"),
    ),
    "fig4-8": (  # X' against L/D_uuv: (a) with size, (b) with heading
        _panel("fig4-8", "a", "X_p", "ld_ratio", "d_ratio"),
        _panel("fig4-8", "b", "X_p", "ld_ratio", "psi_deg"),
    ),
    "fig4-9": (  # HF vs LF surrogate: Y', N' around the submarine, D_sub/D_uuv = 20
        _panel("fig4-9", "a", "Y_p", "R_long", "R_lat"),
        _panel("fig4-9", "b", "N_p", "R_long", "R_lat"),
        _panel("fig4-9", "c", "Y_p", "R_long", "R_lat", fidelity="lf"),
        _panel("fig4-9", "d", "N_p", "R_long", "R_lat", fidelity="lf"),
    ),
    "fig4-10": (  # HF vs LF surrogate: Y' against heading and speed
        _panel("fig4-10", "a", "Y_p", "psi_deg", "u_kn"),
        _panel("fig4-10", "b", "Y_p", "psi_deg", "u_kn", fidelity="lf"),
    ),
    "fig4-11": (  # HF vs LF surrogate: X' against L/D_uuv and heading
        _panel("fig4-11", "a", "X_p", "ld_ratio", "psi_deg"),
        _panel("fig4-11", "b", "X_p", "ld_ratio", "psi_deg", fidelity="lf"),
    ),
}


def r_lat_window(d_ratio: Any, ld_ratio: Any) -> tuple[np.ndarray, np.ndarray]:
    """The R_lat interval (low, high) that constraints (4.4) and (4.5) allow for a UUV of this size,
    clipped to table 4.2's bounds (coefficients as surrogate.constraint_values)."""
    inv_d = 1.0 / np.asarray(d_ratio, dtype=float)
    low = (0.5048 + 0.5 * inv_d + 9.425e-3 * inv_d * np.asarray(ld_ratio, dtype=float)) / 8.575  # (4.4)
    high = (0.5 + 2.0 * inv_d) / 8.575  # (4.5)
    return np.maximum(low, BOUNDS[1, 0]), np.minimum(high, BOUNDS[1, 1])


def mid_window_r_lat(d_ratio: Any, ld_ratio: Any) -> np.ndarray:
    """R_lat in the middle of the window of `r_lat_window`: the stand-in for the thesis's 0.08."""
    low, high = r_lat_window(d_ratio, ld_ratio)
    return 0.5 * (low + high)


def slice_grid(panel: MapPanel, nx: int = 121, ny: int = 81) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inputs (ny, nx, 6) of a panel over table 4.2's range of its two inputs, and the axes (nx,), (ny,)."""
    columns = {name: k for k, name in enumerate(INPUT_NAMES)}
    xs = np.linspace(*BOUNDS[columns[panel.x]], nx)
    ys = np.linspace(*BOUNDS[columns[panel.y]], ny)
    X = np.empty((ny, nx, len(INPUT_NAMES)))
    for name, value in panel.held.items():
        if value != MID_WINDOW:
            X[..., columns[name]] = value
    X[..., columns[panel.x]] = xs[None, :]
    X[..., columns[panel.y]] = ys[:, None]
    if panel.held["R_lat"] == MID_WINDOW and "R_lat" not in (panel.x, panel.y):
        X[..., columns["R_lat"]] = mid_window_r_lat(X[..., columns["d_ratio"]], X[..., columns["ld_ratio"]])
    return X, xs, ys


def evaluate_map(model: Any, panel: MapPanel, nx: int = 121, ny: int = 81) -> dict[str, np.ndarray]:
    """A panel's values (ny, nx), NaN where (4.4)-(4.7) exclude the point, with its axes and inputs.

    model: a loaded model's `.model`; fidelity 'lf' needs one with a low-fidelity part
    (`has_low_fidelity`): the exact LF of an LF-in-the-loop model, or the LF GP of a
    multi-fidelity one (the thesis's "low fidelity surrogate")."""
    X, xs, ys = slice_grid(panel, nx, ny)
    predict = model.predict
    if panel.fidelity == "lf":
        if not has_low_fidelity(model):
            raise ValueError(f"{panel.name}: the model has no low-fidelity part")
        predict = model.low_fidelity if isinstance(model, LFInLoopModel) else model.lf.predict
    flat = X.reshape(-1, len(INPUT_NAMES))
    values = predict(flat)[:, ("X_p", "Y_p", "N_p").index(panel.output)]
    values = np.where(constraints_ok(flat), values, np.nan).reshape(X.shape[:2])
    return {"values": values, "x": xs, "y": ys, "inputs": X}


def has_low_fidelity(model: Any) -> bool:
    """True for an LF-in-the-loop model (the exact LF) and a multi-fidelity one (its LF GP)."""
    return isinstance(model, LFInLoopModel) or hasattr(model, "lf")


def training_points(model: Any, fidelity: str = "hf") -> np.ndarray:
    """The model's training inputs (n, 6): its high-fidelity samples, or for 'lf' the low-fidelity
    samples of a multi-fidelity model (empty if it has none; an LF-in-the-loop model evaluates
    the LF exactly and has no LF samples)."""
    if fidelity == "lf":
        return model.lf.gps[0].X_train_.copy() if hasattr(model, "lf") else np.empty((0, len(INPUT_NAMES)))
    if isinstance(model, LFInLoopModel):
        return model.X.copy()  # its GPs hold the warped inputs
    return model.gps[0].X_train_.copy()
