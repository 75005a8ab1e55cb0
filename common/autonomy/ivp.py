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
or a coupled table at coarse (heading, speed) points (hull avoidance), read linearly in each. Utilities lie in [0, 1].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

try:  # np.interp's compiled core: np.interp adds ~7 us of Python checks a call, a third of a decision
    from numpy._core.multiarray import interp as _interp
except ImportError:  # numpy < 2
    from numpy.core.multiarray import interp as _interp

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
            return _interp(np.abs(d), (0.0, self.peak_width), (1.0, low))
        return _interp(np.abs(d), (0.0, self.peak_width, self.peak_width + self.base_width), (1.0, low, 0.0))


@dataclass(frozen=True)
class Table:
    """A coupled objective sampled at coarse points: `values[i, j]` at headings[i] (any spacing,
    read periodically round the circle) and speeds[j] (ascending), read linearly in each."""

    headings: np.ndarray
    speeds: np.ndarray
    values: np.ndarray

    def _columns(self, psi) -> np.ndarray:
        """Each speed column read at the headings psi: (..., n_speeds). np.interp's periodic
        reading (the same steps, so the same bits), with the headings sorted and wrapped once for
        all columns rather than once a column."""
        period = 2.0 * math.pi
        x = np.asarray(psi, dtype=float) % period
        xp = np.asarray(self.headings, dtype=float) % period
        order = np.argsort(xp)
        xp = xp[order]
        xp = np.concatenate((xp[-1:] - period, xp, xp[0:1] + period))
        fp = np.asarray(self.values, dtype=float)[order]
        fp = np.concatenate((fp[-1:], fp, fp[0:1]))
        out = np.empty(x.shape + (fp.shape[1],))
        for j in range(fp.shape[1]):
            out[..., j] = _interp(x, xp, fp[:, j])
        return out

    def _blend(self, columns: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The columns read linearly at the speeds u (columns[..., j] at each u's point)."""
        j0, wj = _speed_index(self.speeds, u)
        flat = columns.reshape(-1, columns.shape[-1])
        rows = np.arange(len(flat))
        low = flat[rows, j0.ravel()].reshape(j0.shape)
        high = flat[rows, j0.ravel() + 1].reshape(j0.shape)
        return (1 - wj) * low + wj * high

    def __call__(self, psi, u):
        psi, u = np.broadcast_arrays(np.asarray(psi, dtype=float), np.asarray(u, dtype=float))
        return self._blend(self._columns(psi), u)

    def _spread(self, columns: np.ndarray, max_speed: float) -> np.ndarray:
        """Columns read at the grid's headings, spread over the grid's speeds by the speed
        interpolation weights, which depend only on the two speed grids (cached)."""
        return columns @ _speed_weights(tuple(self.speeds), max_speed)

    def on_grid(self, max_speed: float) -> np.ndarray:
        """The table read on the whole decision grid."""
        grid_psi, _ = decision_grid(max_speed)
        return self._spread(self._columns(grid_psi), max_speed)


def _speed_index(coarse: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The coarse interval of each speed (clamped at the ends) and the weight of its upper end."""
    uu = np.minimum(np.maximum(u, coarse[0]), coarse[-1])  # np.clip's values, without its wrapper's cost
    j0 = np.minimum(np.maximum(np.searchsorted(coarse, uu, side="right") - 1, 0), len(coarse) - 2)
    return j0, (uu - coarse[j0]) / (coarse[j0 + 1] - coarse[j0])


@lru_cache(maxsize=32)
def _speed_weights(speeds: tuple, max_speed: float) -> np.ndarray:
    """(n_speeds, S): grid speed k reads the coarse speeds linearly (clamped at the ends)."""
    coarse = np.asarray(speeds)
    _, grid_u = decision_grid(max_speed)
    j0, wj = _speed_index(coarse, grid_u)
    weights = np.zeros((len(coarse), len(grid_u)))
    weights[j0, np.arange(len(grid_u))] += 1 - wj
    weights[j0 + 1, np.arange(len(grid_u))] += wj
    return weights


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


def peak_objective(psi: float, u: float) -> Objective:
    """BHV_Waypoint's objective: a course ZAIC at psi (base width 180 deg) and a speed ZAIC at u
    (peak width u / 2), coupled 50/50."""
    return Objective((psi, u), Zaic(psi, 0.0, math.pi, circular=True), Zaic(u, u / 2.0, max(u, 0.5), summit_delta=0.1))


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


def arbitrate(
    objectives: list[tuple[float, Objective]], max_speed: float, current: tuple[float, float] | None = None
) -> Choice | None:
    """The decision maximising sum_i w_i f_i(psi, u) over the grid, every objective's peak and
    the `current` (heading, speed). Ties go to the first candidate: the peaks in the order given
    (the helm lists them by priority), then the current decision (carry on: what a table alone,
    such as hull avoidance with nothing to avoid, leaves), then the grid in heading-major order
    from -180 deg and 0 m/s. None when no objective is given.

    The separable parts add up to H(psi) + S(u), whose maximum over the grid is the maximum of
    each (the same first cell as the full grid's); only tables need the whole grid."""
    if not objectives:
        return None
    headings, speeds = decision_grid(max_speed)
    n_psi, n_u = len(headings), len(speeds)
    peaks = [(i, o.peak) for i, (_, o) in enumerate(objectives) if o.peak is not None]
    if current is not None:
        peaks.append((-1, current))
    # each function is evaluated once on the grid's values and the peaks' together (np.interp
    # reads every point alone, so the bits are those of two calls), then split
    all_psi = np.concatenate((headings, [p[0] for _, p in peaks]))
    all_u = np.concatenate((speeds, [p[1] for _, p in peaks]))
    pk_psi, pk_u = all_psi[n_psi:], all_u[n_u:]
    pk_total = np.zeros(len(peaks))
    h_sum = np.zeros(n_psi)
    s_sum = np.zeros(n_u)
    grid = None
    for weight, objective in objectives:
        if objective.table is not None:
            columns = objective.table._columns(all_psi)
            if len(peaks):
                pk_total += weight * objective.table._blend(columns[n_psi:], pk_u)
            part = weight * objective.table._spread(columns[:n_psi], max_speed)
            grid = part if grid is None else grid + part
            continue
        h, s = objective.separable(all_psi, all_u)
        h_grid, h_pk = (h, h) if objective.heading is None else (h[:n_psi], h[n_psi:])
        s_grid, s_pk = (s, s) if objective.speed is None else (s[:n_u], s[n_u:])
        if len(peaks):
            pk_total += weight * (np.asarray(h_pk) + np.asarray(s_pk))
        h_sum += weight * h_grid
        s_sum += weight * s_grid
    if grid is None:
        i, j = int(np.argmax(h_sum)), int(np.argmax(s_sum))
        best_value = float(h_sum[i] + s_sum[j])
    else:
        grid += h_sum[:, None]
        grid += s_sum[None, :]
        i, j = divmod(int(np.argmax(grid)), n_u)
        best_value = float(grid[i, j])
    if len(peaks):
        k = int(np.argmax(pk_total))
        if pk_total[k] >= best_value:
            return Choice(float(pk_psi[k]), float(pk_u[k]), float(pk_total[k]), peaks[k][0])
    return Choice(float(headings[i]), float(speeds[j]), best_value, -1)
