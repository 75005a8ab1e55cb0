"""Training the LF-in-the-loop surrogate: training designs, HF evaluation, the final fit.

The model is y(x) = LF(x) + delta(x), with LF the exact low fidelity (`hydro.low_fidelity`) and
delta a GP on the HF - LF residuals at the HF samples, on warped inputs (`warping`). Three
designs choose where the HF runs (docs/design.md, "Hydrodynamic fidelities"):

* "sobol": the first n feasible points of a scrambled Sobol sequence (space filling);
* "residual-us": uncertainty sampling q_US = sigma^2 (thesis (2.9)) on the residual GP, maximum
  variance over the outputs (2.31), seeded by the first `n_seed` points of the Sobol design and
  picking `batch` points per round (greedy, conditioning on each pick at fixed
  hyperparameters: sigma does not depend on y);
* "nmmf": thesis Algorithm 1 with the exact LF in the loop. The LF is known everywhere, so the
  look-ahead LF GP of Algorithm 1 is the LF itself and the HF point maximises
  q_AD = |y_HF - y_MF| (2.17) with y_MF = LF + delta and y_HF the HF-only GP, over the training
  std of each output (2.31); seeded like residual-us.
* "envelope": the HF point that most reduces the doubt about the outcome classes of the
  envelopes a user names (`learning.envelope_design`, docs/hydro/envelope-design.md); the
  envelopes are flown by `analysis.envelope_design`, which hands `run_design` its `acquire`.
  Seeded like residual-us.

Every design draws its candidates from the feasible set, so all HF samples satisfy (4.4)-(4.7).
The held-out test set (`validation.HELD_OUT_SEED`, a Latin hypercube) is never a design: a design
seed equal to it is refused and the samples are checked against the held-out points.

Pool mode (`pool_store`, `pool_candidates`) runs a design on HF values that already exist: the
store holds the pool, any other HF run is refused, and the candidates are the pool's unpicked rows.

HF runs go through an `HFStore`, a CSV appended row by row as results arrive, so a killed run
resumes (the designs are deterministic given the HF values, and replay the stored ones).
"""

from __future__ import annotations

import csv
import hashlib
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nearsub.common.hydro import high_fidelity as hydro_hf
from nearsub.common.hydro import low_fidelity as hydro_lf
from nearsub.common.learning.active import candidate_set, initial_design
from nearsub.common.learning.envelope_design import condition_on_mean
from nearsub.common.learning.gp import FINAL_FIT_RESTARTS, MultiOutputGP
from nearsub.common.learning.testproblems import Problem
from nearsub.common.runtime.processes import completed, task_client
from nearsub.common.surrogate import domain
from nearsub.common.surrogate.modelfile import LFInLoopModel
from nearsub.common.surrogate.validation import HELD_OUT_POINTS, HELD_OUT_SEED, latin_hypercube_feasible
from nearsub.common.surrogate.warping import DEFAULT_WARPING, Warping

DESIGNS = ("nmmf", "sobol", "residual-us", "envelope")
DEFAULT_SEED = 1  # seed 0 is the held-out set's (validation.HELD_OUT_SEED)
DEFAULT_N_SEED = 20  # space-filling HF points that seed the adaptive designs
# Optimiser starts of the refits inside an adaptive design (warm-started from the previous
# optimum); the final fit uses FINAL_FIT_RESTARTS.
_CAMPAIGN_RESTARTS = 2
_CANDIDATES_PER_DIM = 500  # about 3000 d box draws, ~500 feasible candidates per pick
HF_DESCRIPTION = (
    # "common/hydro_hf.py" is the mark tools/free_stream.py looks for in a model's provenance.
    "nearsub two-way Hess-Smith panel method with viscous corrections (common/hydro_hf.py, MEDIUM panels); "
    "NOT RANS CFD (docs/hydro/README.md)"
)
LF_DESCRIPTION = "nearsub one-way slender-body model with ITTC-57 friction (common/hydro/low_fidelity.py), exact"


def interaction_problem(
    hf=hydro_hf.hf_coefficients,
    name: str = "uuv-submarine-interaction",
    description: str = "HF: two-way Hess-Smith panels with viscous corrections; LF: one-way slender body + ITTC-57",
) -> Problem:
    """The surrogate's domain (table 4.2, constraints (4.4)-(4.7)) with the LF physics and an HF
    evaluator (default: the HF physics; `nearsub campaign` names its own problem, whose HF is a
    user's CFD, so that its campaign is never filled with panel-method samples)."""
    return Problem(
        name=name,
        bounds=domain.BOUNDS,
        input_names=domain.INPUT_NAMES,
        output_names=domain.OUTPUT_NAMES,
        hf=hf,
        lf=hydro_lf.lf_coefficients,
        constraint=domain.constraint_values,
        description=description,
    )


PROBLEM = interaction_problem()


def sobol_design(n: int, seed: int = DEFAULT_SEED) -> np.ndarray:
    """The first n feasible points of a scrambled Sobol sequence (every prefix space filling, so
    the 100-sample design is the first 100 of the 300-sample one)."""
    check_seed(seed)
    return initial_design(PROBLEM, n, [seed, 0])


def held_out_overlap(X: np.ndarray) -> int:
    """How many rows of X coincide (to 1e-9 of the box width) with held-out validation points."""
    held = latin_hypercube_feasible(HELD_OUT_POINTS, HELD_OUT_SEED)
    width = domain.BOUNDS[:, 1] - domain.BOUNDS[:, 0]
    close = np.all(np.abs(X[:, None, :] - held[None, :, :]) <= 1e-9 * width, axis=2)
    return int(np.any(close, axis=1).sum())


def check_seed(seed: int) -> None:
    """Refuse the held-out set's seed (ValueError naming it)."""
    if seed == HELD_OUT_SEED:
        raise ValueError(f"--seed {seed}: reserved for the held-out validation set; use another seed")


# ----------------------------------------------------------------------------- HF evaluation
def write_samples(path: Path, X: np.ndarray, Y: np.ndarray) -> None:
    """Samples CSV: the inputs and outputs of each HF run, one row each."""
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow([*domain.INPUT_NAMES, *domain.OUTPUT_NAMES])
        writer.writerows(np.column_stack([X, Y]).tolist())


class HFStore:
    """HF results keyed by their exact input row, appended to a CSV as each run finishes.

    Columns: the inputs, the outputs and hf_seconds (wall time of the run). Python's float repr
    round-trips, so a stored row is found again bit for bit."""

    COLUMNS = (*domain.INPUT_NAMES, *domain.OUTPUT_NAMES, "hf_seconds")

    def __init__(self, path: Path | None):
        self.path = Path(path) if path is not None else None
        self.rows: dict[bytes, tuple[np.ndarray, float]] = {}
        if self.path is not None and self.path.exists():
            with open(self.path, newline="") as fh:
                reader = csv.reader(fh)
                if tuple(next(reader, ())) != self.COLUMNS:
                    raise ValueError(f"{self.path}: not an HF sample store (header is not {','.join(self.COLUMNS)})")
                for row in reader:
                    values = np.array([float(v) for v in row])
                    self.rows[self._key(values[:6])] = (values[6:9], float(values[9]))
        elif self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with open(self.path, "w", newline="") as fh:
                csv.writer(fh).writerow(self.COLUMNS)

    @staticmethod
    def _key(x: np.ndarray) -> bytes:
        return np.ascontiguousarray(x, dtype=float).tobytes()

    def get(self, x: np.ndarray) -> np.ndarray | None:
        hit = self.rows.get(self._key(x))
        return None if hit is None else hit[0]

    def add(self, x: np.ndarray, y: np.ndarray, seconds: float) -> None:
        self.rows[self._key(x)] = (np.asarray(y, dtype=float), float(seconds))
        if self.path is not None:
            with open(self.path, "a", newline="") as fh:
                csv.writer(fh).writerow([*map(float, x), *map(float, y), float(seconds)])
                fh.flush()
                os.fsync(fh.fileno())

    @property
    def hf_seconds(self) -> float:
        return sum(seconds for _, seconds in self.rows.values())


def timed_hf(x: np.ndarray) -> tuple[np.ndarray, float]:
    """HF [X', Y', N'] at one input row (6,), and its wall seconds (a picklable task)."""
    start = time.perf_counter()
    y = hydro_hf.hf_coefficients(x[None, :])[0]
    return y, time.perf_counter() - start


Runner = Callable[[np.ndarray, Callable[[int, np.ndarray, float], None]], None]


@contextmanager
def hf_runner(workers: int | None = None, scheduler: str | None = None) -> Iterator[Runner]:
    """A function run(X, done) that runs the HF at each row of X and calls done(i, y, seconds) as
    row i finishes: in this process, on a local Dask cluster of `workers` processes on 127.0.0.1,
    or on the running Dask cluster at `scheduler` (as `nearsub envelope` does). Local workers
    use one BLAS thread."""
    with task_client(workers, scheduler) as client:

        def run(X, done):
            for index, result in completed(client, timed_hf, X):
                done(index, *result)

        yield run


def evaluate_hf(X: np.ndarray, store: HFStore, run: Runner, on_row: Callable[[], None] | None = None) -> np.ndarray:
    """HF outputs (n, 3) at the rows of X: stored rows are reused, the others run (in parallel on
    a cluster) and are stored as each finishes. Rows whose hulls touch come back NaN."""
    X = np.atleast_2d(np.asarray(X, dtype=float))
    missing = [i for i, x in enumerate(X) if store.get(x) is None]

    def done(k: int, y: np.ndarray, seconds: float) -> None:
        store.add(X[missing[k]], y, seconds)
        if on_row is not None:
            on_row()

    if missing:
        run(X[missing], done)
    return np.vstack([store.get(x) for x in X])


def file_reference(path: Path) -> dict[str, Any]:
    """A file as a model's provenance names it: its path relative to the working directory when it
    lies below it, else its name alone (never a temporary folder's path), and its SHA-256."""
    path = Path(path)
    try:
        name = str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        name = path.name
    digest = hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None
    return {"file": name, "sha256": digest}


# ------------------------------------------------------------------------------ pool mode
class NotInPoolError(ValueError):
    """A pool-mode design asked for an HF value the pool does not hold."""


def pool_store(X: np.ndarray, Y: np.ndarray) -> HFStore:
    """An in-memory HF store holding the pool's rows (no HF run behind them: 0 s each)."""
    store = HFStore(None)
    for x, y in zip(np.asarray(X, dtype=float), np.asarray(Y, dtype=float), strict=True):
        store.add(x, y, 0.0)
    return store


def pool_runner(X: np.ndarray, done: Callable[[int, np.ndarray, float], None]) -> None:
    """The runner of pool mode: every HF value must come from the pool."""
    raise NotInPoolError(f"pool mode: {len(X)} HF run(s) asked for outside the pool (first at {X[0].tolist()})")


def pool_candidates(pool: np.ndarray) -> Callable[[int, np.ndarray], np.ndarray]:
    """candidates(draw, chosen): the pool rows not yet in `chosen` (in pool order)."""
    pool = np.asarray(pool, dtype=float)

    def candidates(draw: int, chosen: np.ndarray) -> np.ndarray:
        taken = {np.ascontiguousarray(x).tobytes() for x in chosen}
        return pool[[np.ascontiguousarray(x).tobytes() not in taken for x in pool]]

    return candidates


# ------------------------------------------------------------------------------ the final fit
def finite_rows(X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The samples whose HF and LF are both defined (the HF is NaN where the hulls touch, the LF
    within 1 cm of the hull)."""
    keep = np.all(np.isfinite(Y), axis=1) & np.all(np.isfinite(hydro_lf.lf_coefficients(X)), axis=1)
    return X[keep], Y[keep]


def fit_model(X: np.ndarray, Y: np.ndarray, warping: Warping | None = None, seed: int = DEFAULT_SEED) -> LFInLoopModel:
    """The final LF-in-the-loop fit: FINAL_FIT_RESTARTS starts per output, degenerate optima
    rejected (`gp.all_length_scales_at_bound`)."""
    X, Y = finite_rows(np.asarray(X, dtype=float), np.asarray(Y, dtype=float))
    return LFInLoopModel.fit(X, Y, warping or Warping(DEFAULT_WARPING), n_restarts=FINAL_FIT_RESTARTS, seed=seed)


def provenance(design: str, model: LFInLoopModel, command: str, **extra: Any) -> dict[str, Any]:
    """What a shipped model must say about itself."""
    return {
        "method": f"LF in the loop: exact LF + residual GP (one ARD RBF GP per output on HF - LF), "
        f"design {design!r}; {FINAL_FIT_RESTARTS} optimiser starts per output",
        "design": design,
        "high_fidelity": HF_DESCRIPTION,
        "low_fidelity": LF_DESCRIPTION,
        "warping": model.warping.describe(),
        "hf_samples": int(len(model.X)),
        "command": command,
        **extra,
    }


# ----------------------------------------------------------------------------------- designs
@dataclass(frozen=True)
class DesignSettings:
    """design: one of DESIGNS; budget: HF samples in all; seed: the design's seed (never the
    held-out set's); n_seed: space-filling seed points of the adaptive designs; batch:
    picks per round of residual-us and envelope (nmmf picks one: q_AD has no batch form); stops:
    HF sample counts where a round ends early, so that a prefix of the design is the design of
    that budget (the comparison's 25, 50 and 100)."""

    design: str = "sobol"
    budget: int = 100
    seed: int = DEFAULT_SEED
    n_seed: int = DEFAULT_N_SEED
    batch: int = 10
    stops: tuple[int, ...] = ()

    def __post_init__(self):
        if self.design not in DESIGNS:
            raise ValueError(f"--design {self.design!r}: choose from {', '.join(DESIGNS)}")
        check_seed(self.seed)
        if self.budget < 2:
            raise ValueError(f"--budget {self.budget}: need at least 2 HF samples")
        if not 2 <= self.n_seed <= self.budget:
            raise ValueError(f"--n-seed {self.n_seed}: need 2 <= n_seed <= budget ({self.budget})")
        if self.batch < 1:
            raise ValueError(f"--batch {self.batch}: need at least 1")


def _candidates(seed: int, draw: int) -> np.ndarray:
    """A fresh feasible candidate set (scrambled Sobol, constraints (4.4)-(4.7))."""
    return candidate_set(PROBLEM, _CANDIDATES_PER_DIM, [seed, 1, draw])


# acquire(delta, warping, candidates, k, X, Y) -> k new points: the envelope design's picks.
Acquire = Callable[[MultiOutputGP, Warping, np.ndarray, int, np.ndarray, np.ndarray], np.ndarray]


def _refit(delta: MultiOutputGP | None, warping: Warping, X: np.ndarray, Y: np.ndarray, seed: int) -> MultiOutputGP:
    """The campaign's residual GP on the finite samples, warm-started from the previous fit."""
    X, Y = finite_rows(X, Y)
    if delta is None:
        delta = MultiOutputGP(bounds=warping.bounds, n_restarts=_CAMPAIGN_RESTARTS, seed=seed)
        return delta.fit(warping.forward(X), Y - hydro_lf.lf_coefficients(X))
    return delta.fit(warping.forward(X), Y - hydro_lf.lf_coefficients(X), warm_start=True)


def _scaled(model: MultiOutputGP) -> np.ndarray:
    """sigma_y,i of (2.31): each output's training-data std."""
    return np.array([gp.y_std_ for gp in model.gps])


def residual_us_picks(delta: MultiOutputGP, warping: Warping, candidates: np.ndarray, k: int) -> np.ndarray:
    """k greedy uncertainty-sampling picks (2.9) on the residual GP, maximum normalised variance
    over the outputs (2.31), each conditioned on the earlier picks at fixed hyperparameters
    (placeholder outputs: the posterior mean; sigma does not depend on them)."""
    W = warping.forward(candidates)
    scale = _scaled(delta)
    look, picks = delta, []
    for _ in range(k):
        std = look.predict(W, return_std=True)[1]
        best = int(np.argmax(np.max((std / scale) ** 2, axis=1)))
        picks.append(best)
        look = condition_on_mean(delta, W[picks])
    return candidates[picks]


def nmmf_pick(delta: MultiOutputGP, hf_only: MultiOutputGP, warping: Warping, candidates: np.ndarray) -> np.ndarray:
    """Algorithm 1's HF point with the exact LF: argmax over outputs of q_AD = |y_HF - y_MF| (2.17)
    over sigma_y,i (2.31), y_MF = LF + delta and y_HF the HF-only GP."""
    W = warping.forward(candidates)
    lf = hydro_lf.lf_coefficients(candidates)
    gap = np.abs(hf_only.predict(W) - (lf + delta.predict(W))) / _scaled(hf_only)
    gap[~np.all(np.isfinite(gap), axis=1)] = -np.inf
    return candidates[int(np.argmax(np.max(gap, axis=1)))][None, :]


def run_design(
    settings: DesignSettings,
    store: HFStore,
    run: Runner,
    warping: Warping | None = None,
    on_row: Callable[[], None] | None = None,
    candidates: Callable[[int, np.ndarray], np.ndarray] | None = None,
    acquire: Acquire | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The HF samples (X, Y) of a design (module doc); HF runs through `store` (reused if there).
    `candidates(draw, chosen)` replaces the fresh Sobol candidates (pool mode, `pool_candidates`);
    `acquire` makes the envelope design's picks (`analysis.envelope_design.acquisition`)."""
    warping = warping or Warping(DEFAULT_WARPING)
    s = settings
    if s.design == "envelope" and acquire is None:
        raise ValueError("--design envelope: name the envelope(s) to aim at (--envelope CONDITIONS)")
    if s.design == "sobol":
        X = sobol_design(s.budget, s.seed)
        return X, evaluate_hf(X, store, run, on_row)
    X = sobol_design(s.n_seed, s.seed)
    Y = evaluate_hf(X, store, run, on_row)
    delta = hf_only = None
    draw = 0
    while len(X) < s.budget:
        draw += 1
        delta = _refit(delta, warping, X, Y, s.seed)
        pool = _candidates(s.seed, draw) if candidates is None else candidates(draw, X)
        k = min([s.batch, s.budget - len(X), *(stop - len(X) for stop in s.stops if stop > len(X))])
        if s.design == "residual-us":
            new = residual_us_picks(delta, warping, pool, k)
        elif s.design == "envelope":
            new = acquire(delta, warping, pool, k, X, Y)
        else:
            keep = np.all(np.isfinite(Y), axis=1)
            if hf_only is None:
                hf_only = MultiOutputGP(bounds=warping.bounds, n_restarts=_CAMPAIGN_RESTARTS, seed=s.seed + 2000)
                hf_only.fit(warping.forward(X[keep]), Y[keep])
            else:
                hf_only.fit(warping.forward(X[keep]), Y[keep], warm_start=True)
            new = nmmf_pick(delta, hf_only, warping, pool)
        X = np.vstack([X, new])
        Y = np.vstack([Y, evaluate_hf(new, store, run, on_row)])
    return X, Y
