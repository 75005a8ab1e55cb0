"""Objective functions over the helm's decision space (heading, speed) and their arbitration.

pHelmIvP's semantics (the MOOS-IvP helm documentation, Benjamin et al.): every active behaviour
hands the helm an objective function over the decision space with a priority weight, and the
helm takes the decision that maximises the weighted sum. nearsub solves it by brute force
instead of interval programming (docs/design.md, "The helm"): the sum is evaluated on a grid of
1 deg x 0.05 m/s plus, as extra candidates, the exact peak of every objective, so a single
behaviour is obeyed exactly (not rounded to the grid) and the result is the same as the
behaviour's own decision, bit for bit.

An objective is a separable part, a_h f_h(psi) + a_s f_s(u) (the ZAIC peak functions of
MOOS-IvP, coupled by the weights a_h + a_s = 1, as BHV_Waypoint couples course and speed 50/50),
plus optionally a coupled table over a coarse (heading, speed) grid (hull avoidance), read by
bilinear interpolation. Utilities lie in [0, 1].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

HEADING_STEP_DEG = 1.0  # the decision grid: 1 deg x 0.05 m/s (docs/design.md, "The helm")
SPEED_STEP = 0.05


@dataclass(frozen=True)
class Zaic:
    """A ZAIC peak function (MOOS-IvP's ZAIC_PEAK): 1 at `summit`, falling linearly by
    `summit_delta` across `peak_width` on either side, then to 0 across `base_width`. Headings
    measure the distance the short way round the circle."""

    summit: float
    peak_width: float = 0.0
    base_width: float = math.inf
    summit_delta: float = 0.0
    circular: bool = False

    def __call__(self, value):
        d = np.asarray(value, dtype=float) - self.summit
        if self.circular:
            d = (d + math.pi) % (2.0 * math.pi) - math.pi
        low = 1.0 - self.summit_delta
        if math.isinf(self.base_width):
            return np.interp(np.abs(d), (0.0, self.peak_width), (1.0, low))
        return np.interp(np.abs(d), (0.0, self.peak_width, self.peak_width + self.base_width), (1.0, low, 0.0))


@dataclass(frozen=True)
class Table:
    """A coupled objective sampled on a coarse grid: `values[i, j]` at headings[i] (evenly spaced,
    the whole circle) and speeds[j] (ascending); read bilinearly, periodic in heading."""

    headings: np.ndarray
    speeds: np.ndarray
    values: np.ndarray

    def __call__(self, psi, u):
        wi, i0, i1, wj, j0 = _weights(
            self.headings, self.speeds, np.asarray(psi, dtype=float), np.asarray(u, dtype=float)
        )
        v = self.values
        return (1 - wi) * ((1 - wj) * v[i0, j0] + wj * v[i0, j0 + 1]) + wi * ((1 - wj) * v[i1, j0] + wj * v[i1, j0 + 1])

    def on_grid(self, max_speed: float) -> np.ndarray:
        """The table read on the whole decision grid: two small matrix products with the
        interpolation weights, which depend only on the two grids (cached)."""
        rows, cols = _grid_weights(len(self.headings), float(self.headings[0]), tuple(self.speeds), max_speed)
        return rows @ self.values @ cols


def _weights(headings, speeds, psi, u):
    n = len(headings)
    fi = ((psi - headings[0]) / (2.0 * math.pi / n)) % n
    i0 = np.floor(fi).astype(int) % n
    wi = fi - np.floor(fi)
    uu = np.clip(u, speeds[0], speeds[-1])
    j0 = np.clip(np.searchsorted(speeds, uu, side="right") - 1, 0, len(speeds) - 2)
    wj = (uu - speeds[j0]) / (speeds[j0 + 1] - speeds[j0])
    return wi, i0, (i0 + 1) % n, wj, j0


@lru_cache(maxsize=32)
def _grid_weights(n: int, first: float, speeds: tuple, max_speed: float) -> tuple[np.ndarray, np.ndarray]:
    """(H, n) and (m, S) matrices: grid heading i reads coarse headings bilinearly, and so on."""
    headings = first + np.arange(n) * (2.0 * math.pi / n)
    coarse_speeds = np.asarray(speeds)
    grid_psi, grid_u = decision_grid(max_speed)
    wi, i0, i1, _, _ = _weights(headings, coarse_speeds, grid_psi, np.zeros_like(grid_psi))
    rows = np.zeros((len(grid_psi), n))
    rows[np.arange(len(grid_psi)), i0] += 1 - wi
    rows[np.arange(len(grid_psi)), i1] += wi
    _, _, _, wj, j0 = _weights(headings, coarse_speeds, np.zeros_like(grid_u), grid_u)
    cols = np.zeros((len(coarse_speeds), len(grid_u)))
    cols[j0, np.arange(len(grid_u))] += 1 - wj
    cols[j0 + 1, np.arange(len(grid_u))] += wj
    return rows, cols


@dataclass(frozen=True)
class Objective:
    """One behaviour's objective function: two ZAICs coupled by `heading_weight` and its
    complement (one of them may be None: indifferent in that variable), or a coupled `table`
    alone. `peak` is the decision it prefers (None for a table)."""

    peak: tuple[float, float] | None
    heading: Zaic | None = None
    speed: Zaic | None = None
    heading_weight: float = 0.5
    table: Table | None = None

    def separable(self, psi, u):
        """(heading part over psi, speed part over u), each already weighted."""
        h = 0.0 if self.heading is None else self.weights()[0] * self.heading(psi)
        s = 0.0 if self.speed is None else self.weights()[1] * self.speed(u)
        return h, s

    def weights(self) -> tuple[float, float]:
        if self.heading is None:
            return 0.0, 1.0
        if self.speed is None:
            return 1.0, 0.0
        return self.heading_weight, 1.0 - self.heading_weight

    def __call__(self, psi, u):
        if self.table is not None:
            return self.table(psi, u)
        h, s = self.separable(psi, u)
        return np.asarray(h) + np.asarray(s)


def peak_objective(psi: float, u: float, heading_base: float = math.pi, speed_peak: float | None = None) -> Objective:
    """BHV_Waypoint's objective: a course ZAIC at psi (base width 180 deg) and a speed ZAIC at u
    (peak width u / 2), coupled 50/50."""
    return Objective(
        (psi, u),
        Zaic(psi, 0.0, heading_base, circular=True),
        Zaic(u, u / 2.0 if speed_peak is None else speed_peak, max(u, 0.5), summit_delta=0.1),
    )


@lru_cache(maxsize=8)
def decision_grid(max_speed: float) -> tuple[np.ndarray, np.ndarray]:
    """Headings [-180, 180) deg and speeds [0, max_speed] m/s of the decision grid, in radians and m/s."""
    headings = np.radians(np.arange(-180.0, 180.0, HEADING_STEP_DEG))
    speeds = np.round(np.arange(0.0, max_speed + SPEED_STEP / 2, SPEED_STEP), 10)
    headings.setflags(write=False)
    speeds.setflags(write=False)
    return headings, speeds


@dataclass(frozen=True)
class Choice:
    psi: float
    u: float
    utility: float
    winner: int  # index of the objective whose peak was chosen, or -1 for a grid cell


def arbitrate(objectives: list[tuple[float, Objective]], max_speed: float) -> Choice | None:
    """The decision maximising sum_i w_i f_i(psi, u) over the grid and every objective's peak.
    Ties go to the first candidate: the peaks in the order given (the helm lists them by
    priority), then the grid in heading-major order from -180 deg and 0 m/s. None when no
    objective is given.

    The separable parts add up to H(psi) + S(u), whose maximum over the grid is the maximum of
    each (the same first cell as the full grid's); only tables need the whole grid."""
    if not objectives:
        return None
    headings, speeds = decision_grid(max_speed)
    peaks = [(i, o.peak) for i, (_, o) in enumerate(objectives) if o.peak is not None]
    pk_psi = np.array([p[0] for _, p in peaks])
    pk_u = np.array([p[1] for _, p in peaks])
    pk_total = np.zeros(len(peaks))
    h_sum = np.zeros(len(headings))
    s_sum = np.zeros(len(speeds))
    grid = None
    for weight, objective in objectives:
        if len(peaks):
            pk_total += weight * objective(pk_psi, pk_u)
        if objective.table is not None:
            part = weight * objective.table.on_grid(max_speed)
            grid = part if grid is None else grid + part
            continue
        h, s = objective.separable(headings, speeds)
        h_sum += weight * h
        s_sum += weight * s
    if grid is None:
        i, j = int(np.argmax(h_sum)), int(np.argmax(s_sum))
        best_value = float(h_sum[i] + s_sum[j])
    else:
        grid += h_sum[:, None]
        grid += s_sum[None, :]
        i, j = divmod(int(np.argmax(grid)), len(speeds))
        best_value = float(grid[i, j])
    if len(peaks):
        k = int(np.argmax(pk_total))
        if pk_total[k] >= best_value:
            return Choice(float(pk_psi[k]), float(pk_u[k]), float(pk_total[k]), peaks[k][0])
    return Choice(float(headings[i]), float(speeds[j]), best_value, -1)
