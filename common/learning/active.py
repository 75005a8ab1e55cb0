"""Active learning for GP surrogates: acquisitions, NMMF and its baselines, ask/tell campaigns.

Acquisitions (thesis 2.2.2, 2.3.1): uncertainty sampling q_US = sigma^2 (2.9) and the
absolute-difference inter-model acquisition q_AD = |y_HF - y_MF| (2.17). Each is maximised over
a dense scrambled-Sobol candidate set (about 1000 d feasible points, fresh every selection), and
the best few candidates (HF picks; the best one for the cheap LF picks) are polished with
L-BFGS-B in the unit cube; a polished point that leaves the feasible set is discarded.

Several outputs (section 2.5): every acquisition returns one column per output, normalised by
that output's training-data std (variance for q_US) so outputs are comparable, and one of
round robin (2.30), maximum variance (2.31) or weighted variance (2.32) picks the point.
With one output all three coincide.

Methods (the `method` setting of `CampaignSettings`):

* "nmmf", Algorithm 1: pick n (default 10) temporary LF points by greedy q_US on the LF GP,
  conditioning on each pick at fixed hyperparameters (sigma does not depend on y, so the batch
  needs no LF runs in between), run them as one LF batch, condition the LF GP on them, pick the
  HF point by q_AD, run HF and then LF there, drop the temporary points, refit all GPs.
* "myopic", the myopic multi-fidelity baseline: per HF sample, pick x_HF by q_US on the MF
  variance sigma_MF^2 = sigma_delta^2 (2.9, 2.11) and run HF there; then run LF at x_HF (for
  (2.15)) and at `myopic_lf_picks` (default 1) greedy LF uncertainty-sampling points
  argmax sigma_LF^2 (conditioned on x_HF); keep all LF runs; refit. One-step-ahead picks at
  both fidelities, no look-ahead, no q_AD. With myopic_lf_picks = 0 it keeps exactly one LF run
  per HF sample, like NMMF, and differs from it only in how x_HF is chosen; with
  myopic_lf_picks = n_lookahead it runs as many LF points per HF sample as NMMF (n + 1) and
  keeps them all.
* Two variants, for fair comparisons: `keep_lookahead` makes NMMF keep its temporary LF runs in
  D_LF (n + 1 LF runs kept per HF sample); `exact_lf` replaces the LF GP by the problem's own
  LF function (cheap LFs: the LF "in the loop", as the shipped surrogate does), so no LF runs
  are requested, NMMF's look-ahead is the LF itself (q_AD with y_MF = LF + y_delta) and the
  myopic baseline makes no LF picks.
* "hf-us", single-fidelity uncertainty sampling on the HF-only GP (also the multi-output method).

`Campaign` runs one method as an ask/tell state machine for an external evaluator: `ask()`
returns a `Request` (fidelity 'lf' or 'hf' and the points), `tell(X, Y)` takes the results.
Selections happen inside `tell`, so `ask` is cheap and idempotent. With a path, the full state
(settings, every evaluation, counters, GP hyperparameters, the pending request) is written
atomically after every `tell`; `Campaign.resume` rebuilds the GPs by conditioning at the saved
hyperparameters, so a resumed campaign continues bit-identically.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.stats import qmc

from nearsub.common.learning.gp import MultiOutputGP
from nearsub.common.learning.mfgp import MultiFidelityGP, model_thetas
from nearsub.common.learning.testproblems import Problem

__all__ = [
    "METHODS",
    "SELECTIONS",
    "Campaign",
    "CampaignSettings",
    "Request",
    "candidate_set",
    "initial_design",
    "maximise",
    "run_campaign",
    "select_point",
]

METHODS = ("nmmf", "myopic", "hf-us")
SELECTIONS = ("round-robin", "max-variance", "weighted")
_STATE_VERSION = 1
# L-BFGS-B iterations per polish start: the candidates are already near a maximum.
_POLISH_MAXITER = 30
_FD_STEP = 1e-7  # unit-cube finite-difference step of the polish gradient

Acquisition = Callable[[np.ndarray], np.ndarray]  # X (N, d) -> per-output values (N, k)


# ------------------------------------------------------------------ search space
def _sobol(problem: Problem, n: int, seed: Any) -> np.ndarray:
    lower, upper = problem.bounds[:, 0], problem.bounds[:, 1]
    U = qmc.Sobol(problem.d, scramble=True, seed=np.random.default_rng(seed)).random_base2(
        max(1, math.ceil(math.log2(n)))
    )
    return lower + U * (upper - lower)


def candidate_set(problem: Problem, per_dim: int, seed: Any) -> np.ndarray:
    """Feasible points of a scrambled Sobol set of 2^ceil(log2(per_dim d)) points."""
    X = _sobol(problem, per_dim * problem.d, seed)
    X = X[problem.feasible(X)]
    if not len(X):
        raise RuntimeError(f"{problem.name}: no feasible candidate in {per_dim * problem.d} draws")
    return X


def initial_design(problem: Problem, n: int, seed: Any) -> np.ndarray:
    """First n feasible points of a scrambled Sobol sequence: every prefix is space-filling,
    so the HF design (a prefix) is nested in the LF design, as (2.15) requires."""
    draws = 4 * n
    while True:
        X = _sobol(problem, draws, seed)
        X = X[problem.feasible(X)]
        if len(X) >= n:
            return X[:n]
        draws *= 4


def maximise(
    f: Callable[[np.ndarray], np.ndarray],
    candidates: np.ndarray,
    problem: Problem,
    n_polish: int,
    values: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """argmax of a vectorised f (N, d) -> (N,): best candidate, then L-BFGS-B from the top few."""
    values = f(candidates) if values is None else values
    top = np.argsort(-values, kind="stable")[: max(1, n_polish)]
    best_x, best_v = candidates[top[0]], float(values[top[0]])
    lower, width = problem.bounds[:, 0], problem.bounds[:, 1] - problem.bounds[:, 0]
    eye = np.eye(problem.d)

    def neg_value_and_grad(u):
        # Forward differences, stepping into the box, as one vectorised call of f (d + 1 rows):
        # several times cheaper than scipy's per-row finite differences.
        step = np.where(u + _FD_STEP <= 1.0, _FD_STEP, -_FD_STEP)
        v = f(lower + (u + np.vstack([np.zeros(problem.d), eye * step])) * width)
        return -float(v[0]), -(v[1:] - v[0]) / step

    for i in top[:n_polish]:
        res = minimize(
            neg_value_and_grad,
            (candidates[i] - lower) / width,
            jac=True,
            method="L-BFGS-B",
            bounds=[(0.0, 1.0)] * problem.d,
            options={"maxiter": _POLISH_MAXITER},
        )
        x = lower + np.clip(res.x, 0.0, 1.0) * width
        if -res.fun > best_v and problem.feasible(x)[0]:
            best_x, best_v = x, -float(res.fun)
    return best_x, best_v


def select_point(
    acq: Acquisition,
    strategy: str,
    turn: int,
    candidates: np.ndarray,
    problem: Problem,
    n_polish: int,
) -> np.ndarray:
    """One point from per-output acquisition values by round robin (2.30), maximum variance
    (2.31) or weighted variance (2.32); `turn` is the count of earlier selections (2.30's j)."""
    V = acq(candidates)
    k = V.shape[1]
    if k == 1 or strategy == "round-robin":
        i = turn % k
        return maximise(lambda X: acq(X)[:, i], candidates, problem, n_polish, V[:, i])[0]
    if strategy == "weighted":
        return maximise(lambda X: acq(X).sum(axis=1), candidates, problem, n_polish, V.sum(1))[0]
    if strategy != "max-variance":
        raise ValueError(f"unknown selection {strategy!r}; choose from {SELECTIONS}")
    picks = [maximise(lambda X, i=i: acq(X)[:, i], candidates, problem, n_polish, V[:, i]) for i in range(k)]
    return max(picks, key=lambda pick: pick[1])[0]


def _output_std(model: MultiOutputGP) -> np.ndarray:
    """sigma_y,i of (2.31): population std of each output's training data."""
    return np.array([gp.y_std_ for gp in model.gps])


def _uncertainty(std: Callable[[np.ndarray], np.ndarray], scale: np.ndarray) -> Acquisition:
    """q_US = sigma^2 (2.9) per output, over sigma_y,i^2 (2.31, 2.32)."""
    return lambda X: (std(X) / scale) ** 2


# ------------------------------------------------------------------ campaign
@dataclass(frozen=True)
class Request:
    """An evaluation the campaign needs: run `fidelity` ('lf' or 'hf') at each row of X."""

    fidelity: str
    X: np.ndarray
    index: int


@dataclass(frozen=True)
class CampaignSettings:
    """Everything that defines a campaign besides the problem (saved with its state).

    hf_budget: stop when this many HF samples are in the model (initial design included).
    n_lf0, n_hf0: nested initial design sizes (HF points are the first n_hf0 LF points).
    n_lookahead: NMMF's temporary LF points per HF sample (10 in section 2.4).
    selection: multi-output strategy, one of SELECTIONS.
    n_restarts: optimiser starts per GP refit; refits after the first also start from the
    previous optimum (warm start), which replaces one start.
    candidates_per_dim, n_polish: acquisition search (about 1000 d candidates; HF picks polish
    the top n_polish, LF picks the top one).
    rho: the AR(1) scale, 1.0 (thesis); None learns it (ablation).
    myopic_lf_picks: LF uncertainty-sampling points the myopic baseline adds per HF sample.
    keep_lookahead: NMMF keeps its temporary LF runs in D_LF (variant; Algorithm 1 drops them).
    exact_lf: the model uses the problem's LF function instead of an LF GP (MF methods only).
    """

    method: str = "nmmf"
    hf_budget: int = 50
    n_lf0: int = 20
    n_hf0: int = 5
    n_lookahead: int = 10
    selection: str = "max-variance"
    seed: int = 0
    n_restarts: int = 2
    candidates_per_dim: int = 1000
    n_polish: int = 3
    rho: float | None = 1.0
    myopic_lf_picks: int = 1
    keep_lookahead: bool = False
    exact_lf: bool = False

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"unknown method {self.method!r}; choose from {METHODS}")
        if self.selection not in SELECTIONS:
            raise ValueError(f"unknown selection {self.selection!r}; choose from {SELECTIONS}")
        if not 1 <= self.n_hf0 <= self.n_lf0:
            raise ValueError("need 1 <= n_hf0 <= n_lf0 (the HF design is nested in the LF one)")
        if min(self.n_lookahead, self.n_polish, self.myopic_lf_picks) < 0 or self.n_restarts < 1:
            raise ValueError("n_lookahead, n_polish, myopic_lf_picks must be >= 0, n_restarts >= 1")
        if self.keep_lookahead and self.method != "nmmf":
            raise ValueError("keep_lookahead is an NMMF variant")
        if self.exact_lf and not self.multi_fidelity:
            raise ValueError("exact_lf needs a multi-fidelity method")

    @property
    def multi_fidelity(self) -> bool:
        return self.method != "hf-us"

    @property
    def lf_runs(self) -> bool:
        """True when the campaign requests LF evaluations (an MF method without the exact LF)."""
        return self.multi_fidelity and not self.exact_lf


@dataclass
class _Data:
    """An append-only dataset of one fidelity."""

    X: np.ndarray
    Y: np.ndarray

    def add(self, X: np.ndarray, Y: np.ndarray) -> None:
        self.X = np.vstack([self.X, X])
        self.Y = np.vstack([self.Y, Y])


@dataclass
class _Counters:
    requests: int = 0  # requests issued; tell must answer the latest
    draws: int = 0  # candidate sets drawn: seeds each fresh Sobol set
    turns: dict[str, int] = field(default_factory=lambda: {"lf": 0, "hf": 0})  # (2.30)


class Campaign:
    """One active-learning run of `settings.method` on `problem`, driven by ask/tell.

    path: JSON file written after every `tell` (None: in memory only, for benchmarks).
    """

    def __init__(self, problem: Problem, settings: CampaignSettings | None = None, path: Any = None):
        settings = settings or CampaignSettings()
        if settings.multi_fidelity and problem.lf is None:
            raise ValueError(f"{problem.name} has no LF evaluator; use method 'hf-us'")
        self.problem, self.settings = problem, settings
        self.path = Path(path) if path is not None else None
        d, m = problem.d, problem.n_outputs
        self._lf = _Data(np.empty((0, d)), np.empty((0, m)))
        self._hf = _Data(np.empty((0, d)), np.empty((0, m)))
        self._lookahead: list[dict[str, list]] = []  # NMMF's temporary LF runs, kept on record
        self._counters = _Counters()
        self._fitted = (0, 0)  # (n_lf, n_hf) prefix of the data the model is fitted on
        self._model: MultiFidelityGP | MultiOutputGP | None = None
        design = initial_design(problem, settings.n_lf0 if settings.lf_runs else settings.n_hf0, [settings.seed, 0])
        self._design = design
        if settings.lf_runs:
            self._phase, self._pending = "init-lf", self._request("lf", design)
        else:
            self._phase, self._pending = "init-hf", self._request("hf", design[: settings.n_hf0])
        self._save()

    # ------------------------------------------------------------- public API
    def ask(self) -> Request | None:
        """The pending request, or None when the HF budget is spent (idempotent)."""
        return self._pending

    def tell(self, X: Any, Y: Any) -> None:
        """Results Y (n, m) or (n,) for the pending request's points X; then plan and save."""
        req = self._pending
        if req is None:
            raise RuntimeError("campaign is finished: nothing was asked")
        X = np.asarray(X, dtype=float)
        if X.shape != req.X.shape or not np.allclose(X, req.X, rtol=1e-12, atol=0.0):
            raise ValueError(f"tell() must answer request {req.index} at its points")
        Y = np.asarray(Y, dtype=float).reshape(len(req.X), -1)
        if Y.shape[1] != self.problem.n_outputs or not np.all(np.isfinite(Y)):
            raise ValueError(f"Y must be finite with {self.problem.n_outputs} column(s)")
        X = req.X
        if req.fidelity == "lf":
            if self._phase == "lookahead":
                self._lookahead.append({"X": X.tolist(), "Y": Y.tolist()})
            if self._phase != "lookahead" or self.settings.keep_lookahead:
                self._lf.add(X, Y)
        else:
            self._hf.add(X, Y)
        self._advance(X, Y)
        self._save()

    @property
    def done(self) -> bool:
        return self._pending is None

    @property
    def n_hf(self) -> int:
        """HF samples in the fitted model (the x-axis of figures 2-5 to 2-9)."""
        return self._fitted[1]

    @property
    def model(self) -> MultiFidelityGP | MultiOutputGP | None:
        return self._model

    def data(self, fidelity: str) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the kept (X, Y) of one fidelity (NMMF's temporary runs are not in D_LF)."""
        d = self._lf if fidelity == "lf" else self._hf
        return d.X.copy(), d.Y.copy()

    def predict(self, X: Any) -> np.ndarray:
        """The campaign's HF prediction (n, m): y_MF (2.11), or the HF-only GP mean."""
        if self._model is None:
            raise RuntimeError("no model yet: the initial design has not been told")
        return self._model.predict(np.asarray(X, dtype=float))

    # ------------------------------------------------------------ state machine
    def _request(self, fidelity: str, X: np.ndarray) -> Request:
        self._counters.requests += 1
        return Request(fidelity, np.array(X, dtype=float), self._counters.requests)

    def _advance(self, X: np.ndarray, Y: np.ndarray) -> None:
        s, phase = self.settings, self._phase
        if phase == "init-lf":
            self._phase, self._pending = "init-hf", self._request("hf", self._design[: s.n_hf0])
        elif phase == "init-hf":
            self._refit(warm_start=False)
        elif phase == "lookahead":  # Algorithm 1: LF GP on D_LF + temporaries, then q_AD
            self._pick_hf_by_gap(self._model.condition_lf(X, Y))
        elif phase == "hf" and not s.lf_runs:
            self._refit(warm_start=True)
        elif phase == "hf":  # LF run at the HF point for (2.15); myopic adds its LF US picks
            batch = X
            if s.method == "myopic":
                batch = np.vstack([X, self._greedy_lf(X, s.myopic_lf_picks)])
            self._phase, self._pending = "lf-at-hf", self._request("lf", batch)
        elif phase == "lf-at-hf":  # Algorithm 1: temporaries are out of D_LF (unless kept)
            self._refit(warm_start=True)
        else:
            raise AssertionError(f"unexpected phase {phase!r}")

    def _refit(self, warm_start: bool) -> None:
        self._fit_model(warm_start=warm_start)
        self._plan()

    def _fit_model(self, warm_start: bool, thetas: Any = None) -> None:
        s = self.settings
        n_lf, n_hf = len(self._lf.X), len(self._hf.X)
        if self._model is None:
            if s.multi_fidelity:
                lf = self.problem.lf if s.exact_lf else None
                self._model = MultiFidelityGP(
                    self.problem.bounds, n_restarts=s.n_restarts, seed=s.seed, rho=s.rho, lf=lf
                )
            else:
                self._model = MultiOutputGP(self.problem.bounds, n_restarts=s.n_restarts, seed=s.seed)
        if s.multi_fidelity:
            self._model.fit(self._lf.X, self._lf.Y, self._hf.X, self._hf.Y, warm_start=warm_start, thetas=thetas)
        else:
            self._model.fit(self._hf.X, self._hf.Y, warm_start=warm_start, theta=thetas)
        self._fitted = (n_lf, n_hf)

    def _plan(self) -> None:
        """Choose the next request from the freshly fitted model."""
        s = self.settings
        if self._fitted[1] >= s.hf_budget:
            self._phase, self._pending = "done", None
        elif s.method == "nmmf" and s.n_lookahead and not s.exact_lf:
            temps = self._greedy_lf(np.empty((0, self.problem.d)), s.n_lookahead)
            self._phase, self._pending = "lookahead", self._request("lf", temps)
        elif s.method == "nmmf":  # n = 0, or the exact LF is its own look-ahead: q_AD as it is
            self._pick_hf_by_gap(self._model)
        else:
            model = self._model.delta if s.method == "myopic" else self._model
            scale = _output_std(self._model.hf if s.method == "myopic" else self._model)
            std = lambda Z: model.predict(Z, return_std=True)[1]  # noqa: E731
            x = self._select(_uncertainty(std, scale), "hf")
            self._phase, self._pending = "hf", self._request("hf", x[None, :])

    def _pick_hf_by_gap(self, look: MultiFidelityGP) -> None:
        """The NMMF HF point: argmax q_AD = |y_HF - y_MF| (2.17) with the look-ahead LF GP."""
        scale = _output_std(self._model.hf)
        x = self._select(lambda Z: look.inter_model_gap(Z) / scale, "hf")
        self._phase, self._pending = "hf", self._request("hf", x[None, :])

    def _greedy_lf(self, X_fixed: np.ndarray, n: int) -> np.ndarray:
        """n LF uncertainty-sampling picks (2.9), each conditioned on the earlier ones and on
        X_fixed at fixed hyperparameters. Placeholder outputs are the posterior mean (kriging
        believer): sigma ignores them, and y_std, hence the scaling, barely moves."""
        scale = _output_std(self._model.lf)
        picks = np.empty((0, self.problem.d))
        for _ in range(n):
            extra = np.vstack([X_fixed, picks])
            look = self._model.condition_lf(extra, self._model.lf.predict(extra)) if len(extra) else self._model
            std = lambda Z, g=look.lf: g.predict(Z, return_std=True)[1]  # noqa: E731
            picks = np.vstack([picks, self._select(_uncertainty(std, scale), "lf")])
        return picks

    def _select(self, acq: Acquisition, kind: str) -> np.ndarray:
        s = self.settings
        self._counters.draws += 1
        candidates = candidate_set(self.problem, s.candidates_per_dim, [s.seed, 1, self._counters.draws])
        turn = self._counters.turns[kind]
        self._counters.turns[kind] += 1
        n_polish = s.n_polish if kind == "hf" else min(1, s.n_polish)
        return select_point(acq, s.selection, turn, candidates, self.problem, n_polish)

    # ------------------------------------------------------------------ persistence
    def state(self) -> dict[str, Any]:
        """The full campaign state as JSON-ready data (floats round-trip exactly)."""
        model = None
        if self._model is not None:
            thetas = self._model.thetas if self.settings.multi_fidelity else model_thetas(self._model)
            model = {"thetas": _tolist(thetas), "fitted": list(self._fitted)}
        pending = None
        if self._pending is not None:
            p = self._pending
            pending = {"fidelity": p.fidelity, "X": p.X.tolist(), "index": p.index}
        return {
            "version": _STATE_VERSION,
            "problem": {
                "name": self.problem.name,
                "bounds": self.problem.bounds.tolist(),
                "outputs": list(self.problem.output_names),
            },
            "settings": asdict(self.settings),
            "phase": self._phase,
            "pending": pending,
            "counters": asdict(self._counters),
            "design": self._design.tolist(),
            "lf": {"X": self._lf.X.tolist(), "Y": self._lf.Y.tolist()},
            "hf": {"X": self._hf.X.tolist(), "Y": self._hf.Y.tolist()},
            "lookahead": self._lookahead,
            "model": model,
        }

    def _save(self) -> None:
        if self.path is None:
            return
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "w") as fh:
            json.dump(self.state(), fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)  # atomic: a kill leaves the old or the new state, never half

    @classmethod
    def resume(cls, path: Any, problem: Problem) -> Campaign:
        """Reload a campaign saved at `path`; `problem` must be the one it was started with."""
        path = Path(path)
        with open(path) as fh:
            state = json.load(fh)
        if state.get("version") != _STATE_VERSION:
            raise ValueError(f"{path}: unsupported campaign state version {state.get('version')}")
        saved = state["problem"]
        if saved["name"] != problem.name or not np.array_equal(saved["bounds"], problem.bounds):
            raise ValueError(f"{path} was saved for problem {saved['name']!r} with other bounds")
        self = object.__new__(cls)
        self.problem, self.path = problem, path
        self.settings = CampaignSettings(**state["settings"])
        d, m = problem.d, problem.n_outputs

        def arr(rows, cols):
            return np.array(rows, dtype=float).reshape(-1, cols)

        self._lf = _Data(arr(state["lf"]["X"], d), arr(state["lf"]["Y"], m))
        self._hf = _Data(arr(state["hf"]["X"], d), arr(state["hf"]["Y"], m))
        self._lookahead = state["lookahead"]
        self._counters = _Counters(**state["counters"])
        self._design = arr(state["design"], d)
        self._phase = state["phase"]
        p = state["pending"]
        self._pending = None if p is None else Request(p["fidelity"], arr(p["X"], d), p["index"])
        self._model, self._fitted = None, (0, 0)
        if state["model"] is not None:
            n_lf, n_hf = state["model"]["fitted"]
            full = self._lf, self._hf  # fit on the prefix the saved model had seen
            self._lf = _Data(full[0].X[:n_lf], full[0].Y[:n_lf])
            self._hf = _Data(full[1].X[:n_hf], full[1].Y[:n_hf])
            thetas = state["model"]["thetas"]
            if self.settings.multi_fidelity:
                thetas = {k: np.array(v, dtype=float) for k, v in thetas.items()}
            else:
                thetas = np.array(thetas, dtype=float)
            self._fit_model(warm_start=False, thetas=thetas)
            self._lf, self._hf = full
        return self


def _tolist(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _tolist(v) for k, v in value.items()}
    return np.asarray(value).tolist()


def run_campaign(
    campaign: Campaign,
    problem: Problem,
    on_refit: Callable[[Campaign], None] | None = None,
) -> Campaign:
    """Drive a campaign to its budget with the problem's own evaluators.

    on_refit(campaign) is called once per HF count, after the model is refitted (including the
    initial design), e.g. to record the test error against `campaign.n_hf`.
    """
    seen = campaign.n_hf if campaign.model is not None else None
    if seen is not None and on_refit is not None:
        on_refit(campaign)
    while (req := campaign.ask()) is not None:
        evaluator = problem.lf if req.fidelity == "lf" else problem.hf
        campaign.tell(req.X, evaluator(req.X))
        if campaign.model is not None and campaign.n_hf != seen:
            seen = campaign.n_hf
            if on_refit is not None:
                on_refit(campaign)
    return campaign
