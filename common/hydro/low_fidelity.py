"""Low fidelity "one-way slender" model of the UUV-submarine interaction (docs/design.md, "Physics decisions").

The thesis's low fidelity source was FS-Flow potential flow with ITTC-57 friction (thesis sections
3.4 and 4.4). This replacement, nearsub's own:

1. The flow of the submarine alone: an axisymmetric ring-source panel solution of the SUBOFF hull
   in the stream -U x (Hess & Smith 1967), tabulated once per process on an (x, R) grid around
   the hull and interpolated with bicubic splines. Both vehicles move at the same speed U = u
   through the water, so in the submarine frame the flow is steady (thesis section 4.2.2).
2. The UUV in that flow, one way (the UUV does not disturb the submarine's flow: the thesis's
   "one-way assumption", section 3.5): slender-body strip theory with the Froude-Krylov pressure
   gradient and added-mass terms, which give the exact Munk moment (slender-body theory: Munk 1924;
   Newman 1977, Marine Hydrodynamics; a finite-diameter variant).
3. ITTC-57 friction drag at the strip-averaged local speed (thesis section 4.4, no form factor).

Inputs are rows [R_long, R_lat, u_kn, psi_deg, d_ratio, ld_ratio]; outputs are the UUV body-axis
coefficients [X', Y', N'] (docs/design.md, "Frames, units and signs"): Y' > 0 away from the submarine
and N' > 0 bow turning away, for the UUV on the +y side.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from functools import lru_cache
from math import factorial
from pathlib import Path

import numpy as np
from scipy.interpolate import BSpline, CubicSpline, RectBivariateSpline
from scipy.special import ellipe, ellipk

from nearsub.common.hydro.cache import cache_key, cached_arrays
from nearsub.common.physics import hull as hull_module
from nearsub.common.physics.hull import (
    L_SUB,
    R_SUB,
    SUB_BOW_X,
    SUB_STERN_X,
    Profile,
    explorer_cb_from_nose,
    explorer_radius,
    suboff_profile,
    uuv_dimensions,
)

# Version of this model's physics: bump it with any change that alters lf_coefficients' values.
# Surrogate model files store it (with N_STRIPS, N_FRUSTA) and refuse a different LF.
LF_VERSION = 2
# Kinematic viscosity of sea water at about 15 C [m^2/s] (ITTC 2011, procedure 7.5-02-01-03: 1.1892e-6 at
# 15 C and 35 g/kg salinity).
NU = 1.19e-6
KNOT = 1852.0 / 3600.0  # [m/s]

# Ring-source panels on the SUBOFF profile, nearsub's choice: 960 change the field by at most 1.8e-3 U
# (`_field_grid`).
N_FRUSTA = 240
N_STRIPS = 60  # UUV strips, cosine-spaced; nearsub's choice
# Rows from which the strip model spreads them over numba's threads (`lf_kernel.strip_forces_threaded`,
# the same bits per row). LF increment terms on 2 cores: 1 row 26 -> 28 us, 8 rows 68 -> 46, 750
# rows 7.0 -> 3.0 ms. Processes a launcher or a Dask cluster starts have one thread each
# (`runtime.processes.single_blas_thread`), so only a batch in one process (a sweep) uses the cores.
THREADED_ROWS = 8
_GAUSS_RULES = tuple(np.polynomial.legendre.leggauss(k) for k in (1, 2, 8, 32))


def ittc57(reynolds):
    """ITTC-57 model-ship correlation line C_F = 0.075 / (log10 Re - 2)^2 (ITTC 1957)."""
    return 0.075 / (np.log10(reynolds) - 2.0) ** 2


def ring_source_velocity(x, r, x0, a):
    """Velocity (u_x, u_r) at axial position x, radius r of a ring source of unit total volume flux
    at axial position x0 with radius a (Hess & Smith 1967). Arrays
    broadcast; m = 2B / (A + B) is scipy's elliptic parameter k^2."""
    dx = np.asarray(x) - x0
    big_a = dx**2 + np.asarray(r) ** 2 + np.asarray(a) ** 2
    big_b = 2.0 * a * r
    m = 2.0 * big_b / (big_a + big_b)
    k, e = ellipk(m), ellipe(m)
    root = np.sqrt(big_a + big_b)
    e_term = e / ((big_a - big_b) * root)
    ux = dx * e_term / (2.0 * np.pi**2)
    i0 = 4.0 * e_term
    i1 = (4.0 / big_b) * (big_a * e_term - k / root)
    ur = (r * i0 - a * i1) / (8.0 * np.pi**2)
    return ux, ur


@dataclass(frozen=True)
class RingPanels:
    """Conical frusta between consecutive profile stations and their source densities (per unit
    stream speed) solving the Neumann condition at the frustum midpoints."""

    xa: np.ndarray
    ra: np.ndarray
    xb: np.ndarray
    rb: np.ndarray
    sigma: np.ndarray

    @property
    def lengths(self) -> np.ndarray:
        return np.hypot(self.xb - self.xa, self.rb - self.ra)

    def velocity(self, x, r) -> tuple[np.ndarray, np.ndarray]:
        """Perturbation velocity (u_x, u_r) per unit stream speed at points (x, r)."""
        return _frusta_velocity(self, np.ravel(x), np.ravel(r), self.sigma)


def _frustum_rule(dist_over_length: np.ndarray, self_pair: np.ndarray):
    """Gauss-Legendre nodes on [0, 1] per pair, by distance d over frustum length h: 1 point beyond
    10 lengths (relative error ~ (h/d)^2/24 < 4e-4), 2 beyond 4 (~ (h/d)^4), 8 beyond 1.5, 32 closer;
    a panel's own midpoint gets 16 on each half so the nodes cluster at its integrable log
    singularity."""
    bands = (np.inf, 10.0, 4.0, 1.5, 0.0)
    rules = []
    for (nodes, weights), lo, hi in zip(_GAUSS_RULES, bands[1:], bands[:-1], strict=True):
        mask = (dist_over_length >= lo) & (dist_over_length < hi) & ~self_pair
        rules.append((mask, 0.5 * (nodes + 1.0), 0.5 * weights))
    half_nodes, half_weights = np.polynomial.legendre.leggauss(16)
    t = np.concatenate([0.25 * (half_nodes + 1.0), 0.5 + 0.25 * (half_nodes + 1.0)])
    rules.append((self_pair, t, np.concatenate([0.25 * half_weights] * 2)))
    return rules


def _frusta_velocity(panels: RingPanels, x: np.ndarray, r: np.ndarray, strengths, self_index=None):
    """Sum over frusta of the ring-source integral along each generator (flux 2 pi r sigma per
    unit generator length), with the quadrature of `_frustum_rule`. strengths=False returns the
    influence matrices instead of the sums."""
    xm, rm = 0.5 * (panels.xa + panels.xb), 0.5 * (panels.ra + panels.rb)
    length = panels.lengths
    dist = np.hypot(x[:, None] - xm[None, :], r[:, None] - rm[None, :]) / length[None, :]
    self_pair = np.zeros(dist.shape, dtype=bool)
    if self_index is not None:
        self_pair[np.arange(len(x)), self_index] = True
    ux = np.zeros(dist.shape)
    ur = np.zeros(dist.shape)
    for mask, nodes, weights in _frustum_rule(dist, self_pair):
        i, j = np.nonzero(mask)
        if i.size == 0:
            continue
        xs = panels.xa[j, None] + nodes * (panels.xb - panels.xa)[j, None]
        a = panels.ra[j, None] + nodes * (panels.rb - panels.ra)[j, None]
        flux = 2.0 * np.pi * a * length[j, None] * weights
        u, v = ring_source_velocity(x[i, None], r[i, None], xs, a)
        ux[i, j] = np.sum(flux * u, axis=1)
        ur[i, j] = np.sum(flux * v, axis=1)
    if strengths is False:
        return ux, ur
    return ux @ strengths, ur @ strengths


def solve_ring_panels(profile: Profile) -> RingPanels:
    """Ring-source panel solution of a body of revolution in the unit stream -x (frame of the
    profile). Boundary condition u.n = n_x at each frustum midpoint (the body-frame stream is
    -U x), with the source sheet's own jump sigma/2 on the diagonal."""
    x, r = profile.x, profile.r
    panels = RingPanels(x[:-1], r[:-1], x[1:], r[1:], np.zeros(len(x) - 1))
    length = panels.lengths
    # Outward normal of each frustum: the generator runs nose to tail (towards -x).
    nx = (panels.rb - panels.ra) / length
    nr = -(panels.xb - panels.xa) / length
    xm, rm = 0.5 * (panels.xa + panels.xb), 0.5 * (panels.ra + panels.rb)
    ux, ur = _frusta_velocity(panels, xm, rm, False, self_index=np.arange(len(xm)))
    matrix = nx[:, None] * ux + nr[:, None] * ur + 0.5 * np.eye(len(xm))
    sigma = np.linalg.solve(matrix, nx)
    return RingPanels(panels.xa, panels.ra, panels.xb, panels.rb, sigma)


# --- the tabulated submarine field ---------------------------------------------------------------

# The table's grid (`_field_grid`) as the decimal numbers it is made from [m]: with LF_VERSION (the
# hull) and the panel count, what identifies a table. The nodes computed from them differ in their
# last bits between CPUs (numpy's power kernels), so a table is never recognised by its nodes.
FIELD_GRID = {
    "r_gap": 0.01,  # the table starts 1 cm outside the widest section
    "r_first_step": 0.002,
    "r_growth": 1.12,
    # Outer edge of the table, from the axis and beyond either tip: the interaction increment's
    # cut-off (`interaction.LF_CUT`) plus R_sub plus the longest UUV's length, so every strip of a
    # UUV within the cut-off lies in the table (docs/design.md, "Hydrodynamic fidelities").
    "r_max": 272.0,
    "x_fine_beyond_tips": 15.0,  # 0.15 m spacing from 15 m behind the stern to 15 m ahead of the bow
    "x_fine_step": 0.15,
    "x_far_first_step": 1.0,
    "x_far_growth": 1.06,
}
# Layout of the shipped table's file (`tabulate_field`): bump it with any change to its keys.
FIELD_TABLE_FORMAT = 2
R_FIELD_MIN = R_SUB + FIELD_GRID["r_gap"]
R_FIELD_MAX = FIELD_GRID["r_max"]


def _growing(start: float, first: float, growth: float, end: float) -> np.ndarray:
    """Nodes from start towards end (either side), the first step `first`, each next `growth`
    times longer, the last one at or beyond end."""
    steps = first * growth ** np.arange(400)
    nodes = start + np.sign(end - start) * np.concatenate([[0.0], np.cumsum(steps)])
    return nodes[: np.searchsorted(np.abs(nodes - start), abs(end - start)) + 1]


def _field_grid() -> tuple[np.ndarray, np.ndarray]:
    """(x, R) table nodes: 0.15 m in x beside and near the hull, then 1 m growing by 6 % a node
    beyond the tips; in R, 2 mm at the hull growing by 12 % a node (log-spaced far out), because
    the field varies on the scale of the distance from the hull. The splines then reproduce the
    ring-panel field to about 1.5e-4 U, below the ring solution's own discretisation error (240
    against 960 frusta: at most 1.8e-3 U, 5 cm off the hull at the afterbody joint; median
    6e-5 U), and far out to a small fraction of the field itself."""
    g = FIELD_GRID
    fine = (SUB_STERN_X - g["x_fine_beyond_tips"], SUB_BOW_X + g["x_fine_beyond_tips"])
    far = (SUB_STERN_X - R_FIELD_MAX, SUB_BOW_X + R_FIELD_MAX)
    x = np.unique(
        np.concatenate(
            [
                _growing(fine[0], g["x_far_first_step"], g["x_far_growth"], far[0]),
                np.arange(fine[0], fine[1], g["x_fine_step"]),
                _growing(fine[1], g["x_far_first_step"], g["x_far_growth"], far[1]),
            ]
        )
    )
    return x, _growing(R_FIELD_MIN, g["r_first_step"], g["r_growth"], R_FIELD_MAX)


class FieldTable:
    """The two bicubic splines of `SubmarineField` as one piecewise-polynomial table, for fast
    evaluation of both at many points (the batch engine asks for ~10^5 points a step).

    Both splines have the same knots, so on each knot cell [t_a, t_a+1) x [s_b, s_b+1) they are
    the bicubic polynomials sum_kl c_kl (x - t_a)^k (R - s_b)^l, c_kl the Taylor coefficients at
    the cell's corner (de Boor 2001, A Practical Guide to Splines, chapter X: the B-spline to
    piecewise-polynomial conversion). The compiled kernels (`lf_kernel`) find a point's cell from
    its neighbour's and evaluate both fields by Horner's rule: the same function as
    `RectBivariateSpline.ev` to rounding (about 1e-16; `tests/test_lf_speed.py`), for any
    breakpoints."""

    def __init__(self, ux: RectBivariateSpline, ur: RectBivariateSpline):
        tx, ty, cx = ux.tck
        tx2, ty2, cy = ur.tck
        if not (np.array_equal(tx, tx2) and np.array_equal(ty, ty2)) or ux.degrees != (3, 3) or ur.degrees != (3, 3):
            raise ValueError("FieldTable needs two bicubic splines on the same knots")
        nx, ny = len(tx) - 4, len(ty) - 4
        coefficients = np.stack([cx.reshape(nx, ny), cy.reshape(nx, ny)], axis=-1)  # (nx, ny, 2)
        self.x_breaks, self.r_breaks = tx[3:-3].copy(), ty[3:-3].copy()
        # Interval index = interior breakpoints at or below the point: in [0, cells - 1] as is.
        self.x_inner, self.r_inner = self.x_breaks[1:-1].copy(), self.r_breaks[1:-1].copy()
        self.x_left, self.r_left = self.x_breaks[:-1].copy(), self.r_breaks[:-1].copy()
        # Taylor coefficients in x at each x-cell's left end, still B-spline coefficients in R.
        in_x = BSpline(tx, coefficients, 3)
        dx_terms = [in_x.derivative(k)(self.x_left) / factorial(k) if k else in_x(self.x_left) for k in range(4)]
        cells = np.empty((len(self.x_left), len(self.r_left), 2, 4, 4))  # x cell a, R cell b, field, k, l
        for k, term in enumerate(dx_terms):  # term: (x cells, ny, 2)
            in_r = BSpline(ty, np.moveaxis(term, 1, 0), 3)  # coefficients (ny, x cells, 2)
            for power in range(4):
                value = in_r.derivative(power)(self.r_left) / factorial(power) if power else in_r(self.r_left)
                cells[:, :, :, k, power] = np.moveaxis(value, 0, 1)  # (R cells, x cells, 2) -> (a, b, 2)
        # One cell's 32 coefficients contiguous: a point reads one 256-byte block.
        self.cells = np.ascontiguousarray(cells)

    def values(self, x: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u_x, u_R) at points x, R (1-D arrays), as `ux.ev(x, r), ur.ev(x, r)` (points outside
        the table continue its edge cells' polynomials)."""
        x = np.ascontiguousarray(x, dtype=float)
        r = np.ascontiguousarray(r, dtype=float)
        ux, ur = np.empty(x.size), np.empty(x.size)
        _kernel().field_values(*self.arrays(), x, r, ux, ur)
        return ux, ur

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The kernels' view of the table: cells, interior breakpoints and cell left ends in x and R."""
        return self.cells, self.x_inner, self.r_inner, self.x_left, self.r_left


# The kernel's table arguments when it reads no table (the UUV alone): typed placeholders, and bounds.
_NO_TABLE = (np.zeros((1, 1, 2, 4, 4)), np.zeros(0), np.zeros(0), np.zeros(1), np.zeros(1), np.zeros(4))


def _kernel():
    """The compiled kernels, imported on first use: numba's import costs about a second, which
    processes that never evaluate the LF (the clock, the pid, the logger) do not pay."""
    from nearsub.common.hydro import lf_kernel

    return lf_kernel


@dataclass(frozen=True)
class SubmarineField:
    """Splines of the submarine-alone perturbation velocity (u_x, u_R) per unit stream speed, and
    the same two as one table for fast evaluation (`FieldTable`)."""

    ux: RectBivariateSpline
    ur: RectBivariateSpline
    x_range: tuple[float, float]
    r_range: tuple[float, float]
    table: FieldTable = dataclasses.field(init=False, repr=False, compare=False)
    # The strip kernel's table arguments: the table's arrays and its bounds (x_min, x_max, R_min, R_max).
    kernel_table: tuple = dataclasses.field(init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "table", FieldTable(self.ux, self.ur))
        object.__setattr__(self, "kernel_table", (*self.table.arrays(), np.array([*self.x_range, *self.r_range])))
        _load_kernels(self.table)


def _load_kernels(table: FieldTable) -> None:
    """Load the compiled kernels (compile them, the first run after an install or an edit) with
    the field, once per process: an app's first step then costs no more than the next. numba
    compiles per argument types, which an empty call fixes as the real ones do."""
    empty, strips = np.empty(0), np.empty((1, 1))
    table.values(empty, empty)
    no_rows = (empty,) * 7 + (np.empty(0, dtype=np.int64), strips, strips, strips)
    outputs = (np.empty((0, 3)), np.empty((0, 3)), np.empty(0, dtype=bool))
    _kernel().strip_forces(*no_rows, *table.arrays(), _NO_TABLE[-1], True, True, *outputs)


def submarine_field(n_frusta: int = N_FRUSTA) -> SubmarineField:
    """The ring-panel solution of the full-scale SUBOFF, tabulated once per panel count and process
    (about 3 s)."""
    return _submarine_field(int(n_frusta))


def tabulate_field(n_frusta: int = N_FRUSTA) -> dict[str, np.ndarray]:
    """The ring-panel velocities (u_x, u_R) at every node of `_field_grid`, with what identifies
    them (`field_table_identity`): what `nearsub lf-field` writes and the package ships
    (`nearsub/data/lf-field.npz`)."""
    x, r = _field_grid()
    xx, rr = np.meshgrid(x, r, indexing="ij")
    panels = solve_ring_panels(suboff_profile(n_frusta + 1))
    ux = np.empty(xx.size)
    ur = np.empty(xx.size)
    chunk = 4000
    for start in range(0, xx.size, chunk):
        part = slice(start, start + chunk)
        ux[part], ur[part] = panels.velocity(xx.ravel()[part], rr.ravel()[part])
    identity = {key: np.array(value) for key, value in field_table_identity(n_frusta).items()}
    return {**identity, "x": x, "r": r, "ux": ux, "ur": ur}


def field_table_identity(n_frusta: int) -> dict[str, int | str]:
    """What a field table is, in exact values: its file format, the LF version (the hull and the
    ring-panel solution), the panel count and the grid's parameters as decimal strings."""
    grid = json.dumps(FIELD_GRID, sort_keys=True)  # floats as repr: the shortest exact decimal
    return {"format": FIELD_TABLE_FORMAT, "lf_version": LF_VERSION, "n_frusta": n_frusta, "grid": grid}


def shipped_field_path() -> Path:
    """Where the package ships the field table (package data `data/*`)."""
    from importlib import resources

    return Path(str(resources.files("nearsub.data") / "lf-field.npz"))


def read_field_table(path: Path, n_frusta: int) -> tuple[np.ndarray, ...] | None:
    """The nodes and node velocities (x, r, ux, ur) of the table at `path` when its identity is
    this LF's with `n_frusta` panels, None otherwise (or when it cannot be read). The table is
    read on its own stored nodes: they are the ones its values belong to."""
    try:
        with np.load(path) as table:
            stored = {key: table[key].item() for key in ("format", "lf_version", "n_frusta", "grid")}
            if stored != field_table_identity(n_frusta):
                return None
            return table["x"], table["r"], table["ux"], table["ur"]
    except (OSError, KeyError, ValueError):
        return None


@lru_cache(maxsize=4)
def _submarine_field(n_frusta: int) -> SubmarineField:
    def tabulate() -> tuple[np.ndarray, ...]:
        table = tabulate_field(n_frusta)
        return table["x"], table["r"], table["ux"], table["ur"]

    # Seconds of CPU per process otherwise (a mission's server, sim and helm all need it at
    # start-up): the shipped table, else one computed once per machine (tests/test_hydro_cache.py
    # checks the shipped one is read, and is the ring-panel solution).
    table = read_field_table(shipped_field_path(), n_frusta)
    if table is None:
        identity = json.dumps(field_table_identity(n_frusta), sort_keys=True)
        table = cached_arrays("lf-field", cache_key([__file__, hull_module.__file__], identity), tabulate)
    x, r, ux, ur = table
    shape = (x.size, r.size)
    return SubmarineField(
        RectBivariateSpline(x, r, ux.reshape(shape)),
        RectBivariateSpline(x, r, ur.reshape(shape)),
        (float(x[0]), float(x[-1])),
        (float(r[0]), float(r[-1])),
    )


# --- the UUV: slender-body strips ------------------------------------------------------------------


@lru_cache(maxsize=1)
def _explorer_cb_table() -> CubicSpline:
    """CB from the nose of a unit-diameter Explorer hull against L/D (hull.explorer_cb_from_nose on
    L/D = 3..30 every 0.1, splined): rows with new L/D values then cost no quadrature."""
    ld = np.arange(3.0, 30.05, 0.1)
    return CubicSpline(ld, [explorer_cb_from_nose(float(v), 1.0) for v in ld])


def _strips(ld_ratio: np.ndarray, n_strips: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Strips of Explorer UUVs of unit diameter: body-frame stations xi (ascending, tail to nose,
    cosine-spaced so the tips are resolved), radius r and meridian arc length, (k, strips) each for
    the k distinct L/D values, and each input row's index into them. A vehicle has one L/D, whose
    strips are kept (`_unit_strips`); many hulls at once (training, validation) are computed
    together, element by element, to the same bits."""
    if ld_ratio.size and (ld_ratio == ld_ratio[0]).all():  # one hull (a vehicle): skip the sort
        return (*_unit_strips(float(ld_ratio[0]), n_strips), np.zeros(ld_ratio.size, dtype=np.int64))
    values, index = np.unique(ld_ratio, return_inverse=True)
    table = _unit_strips(float(values[0]), n_strips) if len(values) == 1 else _strip_table(values, n_strips)
    return (*table, index.astype(np.int64))


@lru_cache(maxsize=256)
def _unit_strips(ld: float, n_strips: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    parts = _strip_table(np.array([ld]), n_strips)
    for part in parts:
        part.setflags(write=False)
    return parts


def _strip_table(ld: np.ndarray, n_strips: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """xi, r and arc (len(ld), n_strips) of `_strips` for the L/D values ld."""
    t = 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, n_strips)))[::-1]
    s = ld[:, None] * t
    r = explorer_radius(s, ld[:, None], 1.0)
    xi = _explorer_cb_table()(ld)[:, None] - s
    arc = np.concatenate([np.zeros((len(ld), 1)), np.cumsum(np.hypot(np.diff(xi), np.diff(r)), axis=1)], axis=1)
    return xi, r, arc


def input_columns(inputs) -> tuple[np.ndarray, ...]:
    """Columns of an (n, 6) input array [R_long, R_lat, u_kn, psi_deg, d_ratio, ld_ratio] as SI
    quantities: CB position x, y [m], speed U [m/s], heading psi [rad], D_uuv, L_uuv [m]."""
    rows = np.atleast_2d(np.asarray(inputs, dtype=float))
    if rows.shape[1] != 6:
        raise ValueError(
            f"inputs must have 6 columns [R_long, R_lat, u_kn, psi_deg, d_ratio, ld_ratio], got {rows.shape}"
        )
    diameter, length = uuv_dimensions(rows[:, 4], rows[:, 5])
    return rows[:, 0] * L_SUB, rows[:, 1] * L_SUB, rows[:, 2] * KNOT, np.radians(rows[:, 3]), diameter, length


def _strip_model(inputs, n_strips: int, n_frusta: int | None, hold: bool):
    """The strip model (`lf_kernel.strip_forces`) of input rows: [X', Y', N'] with the submarine
    (None when n_frusta is None: the UUV alone), the UUV alone, and where a point was held."""
    x_c, y_c, speed, psi, diameter, length = (np.ascontiguousarray(c, dtype=float) for c in input_columns(inputs))
    unit_xi, unit_r, unit_arc, strip_row = _strips(length / diameter, n_strips)
    n = len(x_c)
    lf, free, held = np.empty((n, 3)), np.empty((n, 3)), np.empty(n, dtype=bool)
    with_submarine = n_frusta is not None
    table = submarine_field(n_frusta).kernel_table if with_submarine else _NO_TABLE
    kernel = _kernel().strip_forces_threaded if _kernel().THREADED and n >= THREADED_ROWS else _kernel().strip_forces
    kernel(
        x_c, y_c, np.cos(psi), np.sin(psi), diameter, length, ittc57(speed * length / NU),
        strip_row, unit_xi, unit_r, unit_arc, *table, hold, with_submarine, lf, free, held,
    )  # fmt: skip
    return (lf if with_submarine else None), free, held


def lf_coefficients(inputs, *, n_strips: int = N_STRIPS, n_frusta: int = N_FRUSTA) -> np.ndarray:
    """Low-fidelity [X', Y', N'] (n, 3) for input rows [R_long, R_lat, u_kn, psi_deg, d_ratio, ld_ratio].

    Rows whose UUV reaches outside the tabulated field (closer than 1 cm to the submarine's widest
    radius, or beyond the table's reach, R_FIELD_MAX from the axis and from either tip) come back as NaN."""
    return _strip_model(inputs, n_strips, n_frusta, hold=False)[0]


def lf_free_stream(inputs, *, n_strips: int = N_STRIPS) -> np.ndarray:
    """The same model's [X', Y', N'] for the UUV alone at that speed and heading (R_long, R_lat
    ignored): ITTC-57 friction and the slender Munk moment rho Vol U^2 sin psi cos psi
    (Munk 1924). The interaction increment (docs/design.md, "Physics decisions") is lf - lf_free_stream."""
    return _strip_model(inputs, n_strips, None, hold=False)[1]


def lf_increment_terms(inputs, *, n_strips: int = N_STRIPS, n_frusta: int = N_FRUSTA):
    """`lf_coefficients` and `lf_free_stream` of the same rows (n, 3) each, from one placement of
    the strips, and (n,) True where the UUV had a point closer to the submarine's axis than the
    tabulated field (within 1 cm of the widest radius: touching the hull beside the middle body,
    or inside the tapering ends' radius). Those points see the field held at the table's inner
    edge, R_sub + 1 cm, instead of NaN: the interaction in the loop stays defined and continuous
    up to contact (`interaction.interaction_at` flags it; a collision or close call is declared
    there anyway). Rows beyond the table's outer edges are NaN, as in `lf_coefficients`."""
    return _strip_model(inputs, n_strips, n_frusta, hold=True)


def compile_kernels() -> None:
    """Evaluate every path of the LF, and the event geometry the LF's cut-off reads, once, so numba
    compiles their kernels into its on-disk cache now (seconds, once per install) and not in the
    first processes of a mission (`tools/support/kernels.py`, which tools/run.sh and tools/test.sh
    run after installing, calls it with the helm's kernel)."""
    from nearsub.common.physics import proximity

    row = np.array([[0.0, 0.08, 3.0, 1.0, 8.0, 7.0]])  # any valid row: R_long, R_lat, kn, deg, ratios
    lf_coefficients(row)
    lf_free_stream(row)
    lf_increment_terms(row)
    lf_increment_terms(np.repeat(row, THREADED_ROWS, axis=0))  # the batch engine's threaded kernel
    proximity.classify(np.zeros(1), np.full(1, 5.5), np.zeros(1), 1.0, 0.2)  # a pose 0.3 m off the hull
