"""Free-stream table of the high-fidelity model: the UUV alone, for the "increment" interaction
mode (docs/design.md, "Physics decisions").

The increment mode adds to the vehicle's own coefficients only the surrogate's interaction
increment: its prediction minus the same hydrodynamic model's value for the UUV alone at that
hull, speed and heading. The shipped surrogate was trained on `hydro_hf.hf_coefficients`, so its
free stream is `hydro_hf.hf_free_stream`. That depends on
- L/D_uuv (the mesh of the isolated hull),
- psi (the stream's direction),
- and the Reynolds number Re_L = u L_uuv / nu only (friction, ITTC-57): u and D_sub/D_uuv enter
  through Re_L alone, since the isolated body is solved at unit diameter (hydro_hf.isolated_body),
and not on R_long or R_lat. So the table is three-dimensional, over (ld_ratio, psi_deg,
log10 Re_L), and covers every (u, D_sub/D_uuv, L/D_uuv) of table 4.2. A tensor-product cubic
B-spline interpolates it (a few microseconds a point); queries are clamped to the grid, which the
blend weight never leaves (it is zero outside table 4.2's bounds).

A table names the surrogate it belongs to (`surrogate_model_id`, the model's content hash): a
model trained on something else (a user's CFD, the analytic fixture) has a different free stream,
and `interaction.increment_table` refuses to pair them. The table of the model file `M.npz` lives
next to it as `M-free-stream.npz`; the shipped one is nearsub/data/surrogate-free-stream.npz.
Rebuild with `python -m nearsub.tools.free_stream [MODEL]` (`build_table`, `save_table`).
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import scipy
from scipy.interpolate import NdBSpline, make_interp_spline

import nearsub
from nearsub.common.hydro import high_fidelity as hydro_hf
from nearsub.common.hydro.low_fidelity import KNOT, NU, input_columns
from nearsub.common.physics.hull import D_SUB, uuv_dimensions
from nearsub.common.surrogate import domain
from nearsub.common.surrogate import model as sg

FORMAT_NAME = "nearsub.free-stream-table"
FORMAT_VERSION = 1
AXIS_NAMES = ("ld_ratio", "psi_deg", "log10_re")
# Grid points per axis, nearsub's choice from measurements with MEDIUM panels (hf_free_stream at
# 300 off-grid points): 9 x 9 x 7 leaves at most 7.8e-6, 9.3e-7, 2.4e-7 in X', Y', N' (0.2 %,
# 0.4 %, 0.02 % of their largest values); 5 x 5 x 4 left 1.3 % and 2.4 % in X' and Y' (the
# psi |psi| cross-flow drag kinks at psi = 0, hence the 9 headings). The build costs one
# isolated-hull panel solve per L/D (about 0.3 s) and 0.3 ms a point: 2.5 s in all.
GRID = (9, 9, 7)
_CHECK_POINTS = 300  # off-grid points build_table compares with hf_free_stream (`check_inputs`)
_CHECK_SEED = 12345


class FreeStreamFileError(ValueError):
    """A free-stream table file cannot be used: unreadable, foreign or of an unknown version."""


def reynolds(inputs: Any) -> np.ndarray:
    """(n,) Re_L = u L_uuv / nu of input rows [R_long, R_lat, u_kn, psi_deg, d_ratio, ld_ratio],
    exactly as hydro_hf.hf_free_stream computes it (nu of sea water, hydro_lf.NU): the speed and
    length of `input_columns`, without its other four columns (the sim asks every step)."""
    rows = np.atleast_2d(np.asarray(inputs, dtype=float))
    if rows.shape[1] != 6:
        input_columns(rows)  # raises the error that names the columns
    _, length = uuv_dimensions(rows[:, 4], rows[:, 5])
    return rows[:, 2] * KNOT * length / NU


def reynolds_range(bounds: np.ndarray = domain.BOUNDS) -> tuple[float, float]:
    """Smallest and largest Re_L over table 4.2's box: L_uuv = (L/D) D_sub / (D_sub/D_uuv)."""
    u, d, ld = bounds[2] * KNOT, bounds[4], bounds[5]
    return float(u[0] * ld[0] * D_SUB / d[1] / NU), float(u[1] * ld[1] * D_SUB / d[0] / NU)


def _spline(axes: tuple[np.ndarray, ...], values: np.ndarray) -> NdBSpline:
    """Tensor-product cubic interpolating B-spline (not-a-knot ends): one 1-D interpolation per axis,
    since the collocation matrix of a tensor grid is the Kronecker product of the axes' matrices."""
    coefficients, knots = values, []
    for axis, nodes in enumerate(axes):
        spline = make_interp_spline(nodes, coefficients, k=3, axis=axis)
        coefficients = np.moveaxis(spline.c, 0, axis)  # BSpline keeps the spline axis first
        knots.append(spline.t)
    return NdBSpline(tuple(knots), coefficients, 3)


class FreeStreamTable:
    """[X', Y', N'] of the lone UUV on a (ld_ratio, psi_deg, log10 Re_L) grid, with metadata."""

    def __init__(self, axes: tuple[np.ndarray, ...], values: np.ndarray, meta: dict[str, Any]):
        self.axes = tuple(np.asarray(a, dtype=float) for a in axes)
        self.values = np.asarray(values, dtype=float)
        self.meta = meta
        self._lower = np.array([a[0] for a in self.axes])
        self._upper = np.array([a[-1] for a in self.axes])
        self._spline = _spline(self.axes, self.values)

    @property
    def surrogate_model_id(self) -> str | None:
        return self.meta.get("surrogate_model_id")

    @property
    def provenance(self) -> dict[str, Any]:
        return self.meta.get("provenance", {})

    def coordinates(self, inputs: Any) -> np.ndarray:
        """(n, 3) grid coordinates of input rows, clamped to the grid (non-finite ones to its edge)."""
        rows = np.atleast_2d(np.asarray(inputs, dtype=float))
        points = np.empty((len(rows), 3))  # filled column by column: column_stack's values at less cost
        points[:, 0], points[:, 1] = rows[:, 5], rows[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            np.log10(reynolds(rows), out=points[:, 2])
        points = np.where(np.isfinite(points), points, self._lower)
        return np.minimum(np.maximum(points, self._lower), self._upper)  # np.clip's values at less cost

    def coefficients(self, inputs: Any) -> np.ndarray:
        """(n, 3) free-stream [X', Y', N'] at input rows (n, 6) (R_long and R_lat are ignored)."""
        return np.atleast_2d(self._spline(self.coordinates(inputs)))


def grid_axes(grid: tuple[int, int, int] = GRID) -> tuple[np.ndarray, ...]:
    """The table's nodes: L/D and psi over table 4.2's bounds, log10 Re_L over `reynolds_range`."""
    low, high = np.log10(reynolds_range())
    return (
        np.linspace(domain.BOUNDS[5, 0], domain.BOUNDS[5, 1], grid[0]),
        np.linspace(domain.BOUNDS[3, 0], domain.BOUNDS[3, 1], grid[1]),
        np.linspace(low, high, grid[2]),
    )


def _rows_at(ld: np.ndarray, psi: np.ndarray, log10_re: np.ndarray, d_ratio: float = 20.0) -> np.ndarray:
    """Input rows with these L/D, psi and Re_L: any D_sub/D_uuv will do (Re_L carries it), the speed
    follows from u = Re_L nu / L_uuv (it may lie outside 2-5 kn; the free stream does not mind)."""
    length = ld * D_SUB / d_ratio
    u_kn = 10.0**log10_re * NU / length / KNOT
    zeros = np.zeros_like(ld)
    return np.column_stack([zeros, zeros, u_kn, psi, np.full_like(ld, d_ratio), ld])


def check_inputs(axes: tuple[np.ndarray, ...], n: int, seed: int = _CHECK_SEED) -> np.ndarray:
    """n input rows off the grid: L/D at the middles of the grid's cells (farthest from its nodes),
    psi and log10 Re_L uniform over the grid. Few distinct L/D keep it cheap: every new L/D costs
    one isolated-hull panel solve."""
    rng = np.random.default_rng(seed)
    ld_nodes = axes[0]
    ld = rng.choice(0.5 * (ld_nodes[1:] + ld_nodes[:-1]), size=n)
    psi = rng.uniform(axes[1][0], axes[1][-1], size=n)
    log10_re = rng.uniform(axes[2][0], axes[2][-1], size=n)
    return _rows_at(ld, psi, log10_re)


def build_table(
    panels: hydro_hf.Panels = hydro_hf.MEDIUM,
    grid: tuple[int, int, int] = GRID,
    surrogate_model_id: str | None = None,
    surrogate_model: str = "",
    command: str = "",
    check_points: int = _CHECK_POINTS,
) -> FreeStreamTable:
    """Evaluate hydro_hf.hf_free_stream on the grid (with these panels) and check the interpolant
    against direct evaluations at `check_points` off-grid points (`check_inputs`)."""
    started = time.perf_counter()
    axes = grid_axes(grid)
    mesh = np.meshgrid(*axes, indexing="ij")
    values = hydro_hf.hf_free_stream(_rows_at(*(m.ravel() for m in mesh)), panels).reshape(*mesh[0].shape, 3)
    build_seconds = time.perf_counter() - started
    meta: dict[str, Any] = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "axis_names": list(AXIS_NAMES),
        "output_names": list(domain.OUTPUT_NAMES),
        "surrogate_model_id": surrogate_model_id,
    }
    table = FreeStreamTable(axes, values, meta)
    check: dict[str, Any] = {"points": check_points}
    if check_points:
        X = check_inputs(axes, check_points)
        truth = hydro_hf.hf_free_stream(X, panels)
        error = np.abs(table.coefficients(X) - truth)
        check["max_abs_error"] = error.max(axis=0).tolist()
        check["max_abs_value"] = np.abs(truth).max(axis=0).tolist()
        check["seed"] = _CHECK_SEED
    meta["provenance"] = {
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": command,
        "method": "nearsub.common.hydro.high_fidelity.hf_free_stream (the isolated UUV: viscous corrections and the "
        "Munk moment scaled by the Munk efficiency) on a tensor grid; cubic B-spline interpolation, "
        "clamped to the grid",
        "high_fidelity": "nearsub two-way Hess-Smith panel method with viscous corrections (common/hydro_hf.py)",
        "panels": asdict(panels),
        "munk_efficiency": hydro_hf.munk_efficiency(panels),
        "nu": NU,
        "grid": {name: [float(a[0]), float(a[-1]), len(a)] for name, a in zip(AXIS_NAMES, axes, strict=True)},
        "build_seconds": round(build_seconds, 2),
        "check": check,
        "surrogate_model": surrogate_model,
        "software": {"nearsub": nearsub.__version__, "numpy": np.__version__, "scipy": scipy.__version__},
    }
    return table


def save_table(path: str | os.PathLike, table: FreeStreamTable) -> Path:
    """Write the table as an uncompressed .npz (arrays plus JSON metadata), atomically."""
    path = Path(path)
    arrays = {name: axis for name, axis in zip(AXIS_NAMES, table.axes, strict=True)}
    arrays["values"] = table.values
    arrays["metadata"] = np.frombuffer(json.dumps(table.meta, sort_keys=True).encode("utf-8"), dtype=np.uint8)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def load_table(path: str | os.PathLike) -> FreeStreamTable:
    """Read a table written by `save_table` (never executes code: allow_pickle=False)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(bytes(data["metadata"]).decode("utf-8"))
            axes = tuple(data[name] for name in AXIS_NAMES)
            values = data["values"]
    except (OSError, KeyError, ValueError) as exc:
        raise FreeStreamFileError(f"{path}: not a readable free-stream table ({exc})") from None
    if meta.get("format") != FORMAT_NAME or meta.get("version") != FORMAT_VERSION:
        raise FreeStreamFileError(
            f"{path}: format {meta.get('format')!r} version {meta.get('version')!r}, "
            f"expected {FORMAT_NAME!r} version {FORMAT_VERSION}"
        )
    return FreeStreamTable(axes, values, meta)


TABLE_SUFFIX = "-free-stream.npz"


def default_table_path() -> Path:
    """The shipped table, the free stream of the shipped surrogate (package data `data/*`)."""
    return sg.companion_path(sg.default_model_path(), TABLE_SUFFIX)


def table_path_for(model_path: str | os.PathLike) -> Path:
    """Where the table of a model file lives: next to it, `<stem>-free-stream.npz`."""
    return sg.companion_path(model_path, TABLE_SUFFIX)


def find_table(model_id: str | None, model_path: str | os.PathLike | None) -> tuple[FreeStreamTable | None, list[Path]]:
    """The table made for the surrogate `model_id` (`model.find_companion`), or None; also
    returns where it looked."""
    return sg.find_companion(model_id, model_path, TABLE_SUFFIX, load_table)
