"""The envelope design of `nearsub train --design envelope`: HF samples aimed at the outcome
boundary of the envelopes a user names, and the pool-based comparison of the designs
(docs/hydro/envelope-design.md).

Each round flies every named envelope under K posterior function samples of the current residual
GP (`envelope.compute_sampled`), records where the trajectories ask delta, weighs each cell by
the Gini impurity of its K outcomes, and picks the candidates that explain most of the posterior
variance along the doubtful cells' trajectories (`learning.envelope_design.envelope_picks`).
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nearsub.common.analysis.batch import OUTCOMES
from nearsub.common.analysis.envelope import EnvelopeConfig, Sampling, compute_envelope, compute_sampled
from nearsub.common.learning.envelope_design import envelope_picks
from nearsub.common.learning.gp import MultiOutputGP
from nearsub.common.physics.vehicles import get_vehicle
from nearsub.common.surrogate import free_stream as fs
from nearsub.common.surrogate import model as sg
from nearsub.common.surrogate import training as tr
from nearsub.common.surrogate.modelfile import LFInLoopModel
from nearsub.common.surrogate.warping import Warping

DEFAULT_SAMPLES = 8  # posterior samples per round: a split of one in 8 is a Gini impurity of 0.22
DEFAULT_SPEC_GRID = (20, 10)  # cells of a named envelope unless the spec says (docs/hydro/envelope-design.md)
TARGETS_PER_CELL = 8  # points of each cell's trajectories that stand for it in the acquisition
MAX_SPECS = 2
_OUTCOME_CLASSES = len(OUTCOMES) - 1  # infeasible cells never fly

# The keys of an --envelope CONDITIONS and how each value is read.
_RANGE = lambda text: tuple(float(v) for v in text.split(":"))  # noqa: E731  LO:HI (a comma separates keys)
SPEC_KEYS: dict[str, Callable[[str], object]] = {
    "vehicle": lambda text: get_vehicle(text).name,
    "behaviour": str,
    "d_lead": float,
    "gamma": float,
    "sea_state": int,
    "depth": float,
    "u_sub": float,
    "u_ot": float,
    "grid": lambda text: tuple(int(v) for v in text.lower().split("x")),
    "r_long": _RANGE,
    "r_lat": _RANGE,
    "duration": float,
    "dt": float,
}


def parse_spec(text: str) -> EnvelopeConfig:
    """'vehicle=sdv,behaviour=nuv_compensation,grid=20x10' -> EnvelopeConfig (grid DEFAULT_SPEC_GRID
    unless given; ranges as LO:HI). Raises ValueError naming the key and value."""
    values: dict[str, object] = {"grid": DEFAULT_SPEC_GRID}
    for item in filter(None, (part.strip() for part in text.split(","))):
        key, sep, value = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or key not in SPEC_KEYS:
            raise ValueError(f"--envelope {text!r}: {item!r} is not KEY=VALUE with KEY one of {', '.join(SPEC_KEYS)}")
        try:
            values[key] = SPEC_KEYS[key](value.strip())
        except (ValueError, LookupError):
            raise ValueError(f"--envelope {text!r}: {key} = {value.strip()!r} is not a valid value") from None
    try:
        return EnvelopeConfig(**values)
    except ValueError as exc:  # pydantic's ValidationError
        first = exc.errors()[0] if hasattr(exc, "errors") else {"loc": ("?",), "input": text}
        field = ".".join(str(part) for part in first["loc"])
        raise ValueError(f"--envelope {text!r}: {field} = {first.get('input')!r}: {first.get('msg', exc)}") from None


def in_loop_surrogate(model: LFInLoopModel, folder: Path) -> sg.Surrogate:
    """A model in training as a `Surrogate` the batch engine flies, saved in `folder` with a copy
    of the shipped HF free-stream table (the increment mode needs it; it depends on the HF only,
    which every design shares) relabelled with the model's id."""
    path = sg.save_surrogate(folder / "round.npz", model, {"method": "envelope design: a model in training"})
    surrogate = sg.load_surrogate(path)
    shipped = fs.load_table(fs.default_table_path())
    fs.save_table(
        fs.table_path_for(path),
        fs.FreeStreamTable(shipped.axes, shipped.values, {**shipped.meta, "surrogate_model_id": surrogate.model_id}),
    )
    return surrogate


@dataclass
class Doubt:
    """Where an envelope is in doubt: per cell its weight G_c and outcome probabilities, and the
    points (raw inputs) its trajectories asked delta about, each with its cell."""

    weight: np.ndarray
    probability: np.ndarray
    targets: np.ndarray
    cell: np.ndarray


def envelope_doubt(config: EnvelopeConfig, surrogate: sg.Surrogate, samples: int, seed: int) -> Doubt:
    """Fly `config` under `samples` posterior samples and weigh each cell by the Gini impurity of
    its outcomes, 1 - sum_k P_k^2. The cells next to another majority class share, in all, the
    weight of the smallest split K samples can show (one in K: 2 (K - 1) / K^2), which keeps the
    boundary in view when the K samples agree everywhere and adds little when some do not."""
    records: list[tuple[np.ndarray, np.ndarray]] = []
    run = compute_sampled(
        config, Sampling(samples, seed), surrogate=surrogate, on_delta=lambda X, rows: records.append((X, rows))
    )
    n_cells = len(run.r_long) * len(run.r_lat)
    p = run.probabilities()[:, :_OUTCOME_CLASSES]
    flying = p.sum(axis=1) > 0.0
    gini = np.where(flying, 1.0 - np.sum(p * p, axis=1), 0.0)
    majority = np.argmax(p, axis=1).reshape(len(run.r_long), len(run.r_lat))
    boundary = np.zeros_like(majority, dtype=bool)
    for axis in (0, 1):
        differs = np.diff(majority, axis=axis) != 0
        lead, trail = [slice(None)] * 2, [slice(None)] * 2
        lead[axis], trail[axis] = slice(1, None), slice(None, -1)
        boundary[tuple(lead)] |= differs
        boundary[tuple(trail)] |= differs
    boundary = boundary.ravel() & flying
    weight = gini + boundary * (2.0 * (samples - 1) / samples**2 / max(1, int(boundary.sum())))
    targets, cell = _targets(records, n_cells)
    return Doubt(weight, p, targets, cell)


def _targets(records: list[tuple[np.ndarray, np.ndarray]], n_cells: int) -> tuple[np.ndarray, np.ndarray]:
    """TARGETS_PER_CELL points of each cell's recorded queries (over all its samples), evenly
    spaced in the order they were asked, and their cells."""
    if not records:
        return np.empty((0, 6)), np.empty(0, dtype=int)
    X = np.vstack([x for x, _ in records])
    cell = np.concatenate([rows for _, rows in records]) % n_cells
    order = np.argsort(cell, kind="stable")
    X, cell = X[order], cell[order]
    keep = []
    starts = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]])
    for start, end in zip(starts, np.r_[starts[1:], len(cell)], strict=True):
        keep.extend(np.unique(np.linspace(start, end - 1, TARGETS_PER_CELL).round().astype(int)))
    return X[keep], cell[keep]


def acquisition(
    specs: Sequence[EnvelopeConfig],
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    log: list[dict] | None = None,
) -> tr.Acquire:
    """The envelope design's `acquire` for `training.run_design`: each round flies every spec
    under `samples` posterior samples of the current model and picks greedily (module doc).
    `log` collects one entry per round (HF samples, doubtful cells, acquisition values, seconds)."""

    def acquire(delta: MultiOutputGP, warping: Warping, candidates: np.ndarray, k: int, X, Y) -> np.ndarray:
        started = time.perf_counter()
        Xf, Yf = tr.finite_rows(X, Y)
        with tempfile.TemporaryDirectory(prefix="nearsub-envelope-design-") as folder:
            surrogate = in_loop_surrogate(LFInLoopModel(delta, warping, Xf, Yf), Path(folder))
            doubts = [envelope_doubt(config, surrogate, samples, seed) for config in specs]
        offsets = np.cumsum([0] + [len(d.weight) for d in doubts])
        targets = np.vstack([d.targets for d in doubts])
        cell = np.concatenate([d.cell + offset for d, offset in zip(doubts, offsets, strict=False)])
        weight = np.concatenate([d.weight for d in doubts])
        if len(targets):
            picks, values = envelope_picks(
                delta, warping.forward(candidates), warping.forward(targets), cell, weight, k
            )
        else:  # no trajectory reaches the residual's box: nothing to aim at, take the candidates in order
            picks, values = list(range(k)), [0.0] * k
        if log is not None:
            log.append(
                {
                    "hf_samples": len(X),
                    "doubtful_cells": [
                        int(np.sum((d.probability.max(axis=1) < 1.0) & (d.probability.sum(axis=1) > 0.0)))
                        for d in doubts
                    ],
                    "weight_sum": [float(d.weight.sum()) for d in doubts],
                    "values": values,
                    "seconds": round(time.perf_counter() - started, 1),
                }
            )
        return candidates[picks]

    return acquire


# --- The pool-based comparison ----------------------------------------------------------------
COMPARE_DESIGNS = ("sobol", "residual-us", "nmmf", "envelope")
COMPARE_BUDGETS = (25, 50, 100)
COMPARE_N_SEED = 10  # space-filling seed points of every adaptive design in the comparison
COMPARE_BATCH = {"residual-us": 10, "envelope": 25}  # picks per round (nmmf: one); envelope: 4 rounds of flying


def reference_model(X: np.ndarray, Y: np.ndarray, path: Path) -> LFInLoopModel:
    """The reference: the final fit (`training.fit_model`) on the whole pool, kept at `path` and
    reused while the pool is the same (its samples are in the model file)."""
    if path.exists():
        loaded = sg.load_surrogate(path).model
        if isinstance(loaded, LFInLoopModel) and np.array_equal(loaded.X, tr.finite_rows(X, Y)[0]):
            return loaded
    model = tr.fit_model(X, Y)
    sg.save_surrogate(path, model, tr.provenance("pool (reference)", model, "nearsub train --compare"))
    return model


def mean_outcomes(model: LFInLoopModel, configs: Sequence[EnvelopeConfig]) -> list[np.ndarray]:
    """The outcome code of every cell of each envelope, flown with the model's mean."""
    with tempfile.TemporaryDirectory(prefix="nearsub-envelope-compare-") as folder:
        surrogate = in_loop_surrogate(model, Path(folder))
        return [compute_envelope(config, surrogate).result.outcome for config in configs]


def misclassified(outcome: np.ndarray, reference: np.ndarray) -> tuple[int, int]:
    """Cells whose outcome class differs from the reference's, and the feasible cells."""
    feasible = reference != OUTCOMES.index("infeasible")
    return int(np.sum(outcome[feasible] != reference[feasible])), int(feasible.sum())


@dataclass
class DesignRun:
    """One design of the comparison: its picks (pool rows in order), wall time, round log."""

    design: str
    X: np.ndarray
    Y: np.ndarray
    seconds: float
    rounds: list[dict]


def run_pool_design(
    design: str,
    X: np.ndarray,
    Y: np.ndarray,
    configs: Sequence[EnvelopeConfig],
    budgets: Sequence[int] = COMPARE_BUDGETS,
    samples: int = DEFAULT_SAMPLES,
    seed: int = tr.DEFAULT_SEED,
) -> DesignRun:
    """One design run to the largest budget on the pool (X, Y), with rounds ending at every budget
    so that each budget's design is a prefix."""
    settings = tr.DesignSettings(
        design=design,
        budget=max(budgets),
        seed=seed,
        n_seed=COMPARE_N_SEED,
        batch=COMPARE_BATCH.get(design, 1),
        stops=tuple(budgets),
    )
    rounds: list[dict] = []
    acquire = acquisition(configs, samples, log=rounds) if design == "envelope" else None
    started = time.perf_counter()
    picked, values = tr.run_design(
        settings, tr.pool_store(X, Y), tr.pool_runner, candidates=tr.pool_candidates(X), acquire=acquire
    )
    return DesignRun(design, picked, values, time.perf_counter() - started, rounds)


def score_design(run: DesignRun, configs: Sequence[EnvelopeConfig], references: Sequence[np.ndarray], budgets):
    """Rows (design, budget, vehicle, misclassified, feasible, rate, fit seconds) of one design."""
    rows = []
    for budget in budgets:
        started = time.perf_counter()
        model = tr.fit_model(run.X[:budget], run.Y[:budget])
        fit_seconds = time.perf_counter() - started
        for config, outcome, reference in zip(configs, mean_outcomes(model, configs), references, strict=True):
            wrong, feasible = misclassified(outcome, reference)
            rows.append(
                {
                    "design": run.design,
                    "budget": budget,
                    "envelope": config.label(),
                    "vehicle": config.vehicle,
                    "misclassified": wrong,
                    "feasible_cells": feasible,
                    "rate": wrong / feasible if feasible else 0.0,
                    "fit_seconds": round(fit_seconds, 1),
                    "design_seconds": round(run.seconds, 1),
                }
            )
    return rows


def comparison_table(results: Sequence[dict], configs: Sequence[EnvelopeConfig]) -> str:
    """Markdown: one row per design and budget, the misclassified cells of each envelope (count of
    the feasible cells and rate) and the design's wall time (to the largest budget)."""
    order = {name: k for k, name in enumerate(COMPARE_DESIGNS)}
    head = ["design", "HF budget", *(f"{c.label()}: misclassified" for c in configs), "design time [s]"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for result in sorted(results, key=lambda r: order.get(r["design"], len(order))):
        for budget in sorted({row["budget"] for row in result["rows"]}):
            cells = []
            for config in configs:
                row = next(r for r in result["rows"] if r["budget"] == budget and r["envelope"] == config.label())
                cells.append(f"{row['misclassified']} / {row['feasible_cells']} ({100 * row['rate']:.1f} %)")
            seconds = result["rows"][0]["design_seconds"]
            lines.append(f"| {result['design']} | {budget} | " + " | ".join(cells) + f" | {seconds:.0f} |")
    return "\n".join(lines)
