"""Safe operating envelopes (thesis sections 5.11 and 6.4): where around the submarine a UUV, under
given conditions, stays safe, strays far, has a close call or collides.

One run per grid cell: the UUV starts at the cell's position with heading 0 and U_UUV = U_sub +
U_ot, and follows a track-line parallel to the submarine axis through its start, for `duration`
seconds. Each cell is classified, in priority order, as collision, close call, large stray or
safe (thesis section 5.11.2; docs/design.md, "Physics decisions"; `physics.proximity`); cells
whose UUV starts inside or touching the hull are infeasible. The cells run together in the batch
engine (`batch.run_batch`), which calls the functions the apps call, so a cell replayed as a
mission (`cell_mission`) ends the same way.

The default grid spans R_long = x / L_sub from -0.8 to 0.8 (past both ends of the hull) and R_lat =
y / L_sub from 0.05 (inside the middle body, outside the tapered ends) to 0.12, beyond the
surrogate's domain (table 4.2: R_lat <= 0.105; constraint (4.5) ends it 2 D_uuv off the hull).
The outline is symmetric and so are the waves (section 5.8), so one side is enough.

A sweep over many configurations runs one configuration per task, in this process or on a Dask
cluster (`sweep`).

An uncertainty-aware envelope (`sampled_envelope`) flies every cell under K posterior function
samples of the surrogate's residual (`surrogate.sampling`), each one force field for the whole run,
as one batch of cells x K, and gives per cell the probability of each outcome and quantiles of the
closest approach.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from nearsub.common.analysis.batch import OUTCOMES, BatchResult, run_batch
from nearsub.common.mission.schema import BEHAVIOURS, Mission, mission_from_dict
from nearsub.common.physics import proximity as events
from nearsub.common.physics import waves
from nearsub.common.physics.hull import D_SUB, L_SUB
from nearsub.common.physics.vehicles import get_vehicle
from nearsub.common.runtime.processes import completed, task_client
from nearsub.common.surrogate import domain
from nearsub.common.surrogate.maps import r_lat_window
from nearsub.common.surrogate.model import Surrogate, load_surrogate
from nearsub.common.surrogate.sampling import DEFAULT_FEATURES, draw_samples

# The track-line runs this far ahead of the start: the lead point never reaches its end in a sweep.
TRACK_AHEAD = 1000.0  # [m]


class EnvelopeConfig(BaseModel):
    """Everything that defines one envelope. Defaults: thesis figure 5-10 for the small UUV."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    vehicle: str = "remus100"
    behaviour: Literal[BEHAVIOURS] = "waypoints"
    d_lead: float = Field(default=3.0, gt=0, description="d_lead in UUV lengths (thesis: 3 L_uuv)")
    gamma: float | None = Field(default=None, gt=0, description="N_uv compensation gain; default (6.4)")
    sea_state: int = Field(default=0, ge=0, le=6, description="thesis table 5.1")
    depth: float = Field(default=50.0, gt=0, description="UUV operating depth [m]")
    u_sub: float = Field(default=1.5, gt=0, description="submarine speed [m/s] (thesis: 1.5)")
    u_ot: float = Field(default=0.0, description="overtaking speed U_UUV - U_sub [m/s]")
    grid: tuple[int, int] = Field(default=(40, 20), description="cells along R_long and R_lat")
    r_long: tuple[float, float] = (-0.8, 0.8)
    r_lat: tuple[float, float] = (0.05, 0.12)
    duration: float = Field(default=120.0, gt=0, description="simulated seconds per cell")
    dt: float = Field(default=0.1, gt=0, le=1.0, description="base step [s]")
    model: str = Field(default="", description="surrogate model file; empty = the shipped model")

    @property
    def uuv_length(self) -> float:
        return get_vehicle(self.vehicle).length

    @property
    def uuv_speed(self) -> float:
        return self.u_sub + self.u_ot

    def label(self) -> str:
        """One line for plot titles."""
        v = get_vehicle(self.vehicle)
        parts = [v.name, self.behaviour.replace("_", " "), f"d_lead = {self.d_lead:g} L"]
        if self.behaviour.endswith("nuv_compensation"):
            parts.append(f"gamma = {self.gamma:g}" if self.gamma else "gamma (6.4)")
        parts.append(f"sea state {self.sea_state}" + (f", {self.depth:g} m" if self.sea_state >= 2 else ""))
        if self.u_ot:
            parts.append(f"U_ot = {self.u_ot:g} m/s")
        return ", ".join(parts)

    def slug(self) -> str:
        """A file name stem that tells the configurations of a sweep apart."""
        parts = [get_vehicle(self.vehicle).name, self.behaviour, f"dlead{self.d_lead:g}L"]
        if self.gamma is not None:
            parts.append(f"gamma{self.gamma:g}")
        parts.append(f"ss{self.sea_state}-{self.depth:g}m")
        if self.u_ot:
            parts.append(f"uot{self.u_ot:g}")
        if self.u_sub != 1.5:
            parts.append(f"usub{self.u_sub:g}")
        return "_".join(parts)


def mission_data(config: EnvelopeConfig, x: float = 0.0, y: float = 0.0, name: str = "envelope") -> dict:
    """The mission (as the dict of a mission file) of the cell whose UUV starts at (x, y)."""
    speed = config.uuv_speed
    helm: dict[str, Any] = {
        "behaviour": config.behaviour,
        "legs": [
            {
                "name": "track",
                "points": [[x + TRACK_AHEAD, y]],
                "speed": speed,
                "lead": config.d_lead * config.uuv_length,
                "lead_to_start": True,
            }
        ],
    }
    if config.gamma is not None:
        helm["gamma"] = config.gamma
    return {
        "name": name,
        "description": f"envelope cell at ({x:g}, {y:g}): {config.label()}",
        "vehicle": config.vehicle,
        "dt": config.dt,
        "time_limit": config.duration,
        "start": {"x": x, "y": y, "psi_deg": 0.0, "speed": speed},
        "environment": {
            "u_sub": config.u_sub,
            "submarine": True,
            "sea_state": config.sea_state,
            "depth": config.depth,
        },
        "surrogate": {"model": config.model},
        "apps": {"helm": helm},
    }


def cell_mission(config: EnvelopeConfig, x: float, y: float, name: str = "envelope") -> Mission:
    """The cell at (x, y) as a mission of its own, to replay it through the launcher."""
    return mission_from_dict(mission_data(config, x, y, name), f"envelope cell ({x:g}, {y:g})")


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(float(value)) if isinstance(value, float) else str(value)
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"no TOML form for {value!r}")


def mission_toml(data: dict) -> str:
    """A mission dict as a TOML file: scalars first, then one [table] per section."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for key, table in data.items():
        if isinstance(table, dict):
            lines.append(f"\n[{key}]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def grid_axes(config: EnvelopeConfig) -> tuple[np.ndarray, np.ndarray]:
    """Cell centres along R_long and R_lat (both ends included)."""
    (n_long, n_lat), (long_lo, long_hi), (lat_lo, lat_hi) = config.grid, config.r_long, config.r_lat
    return np.linspace(long_lo, long_hi, n_long), np.linspace(lat_lo, lat_hi, n_lat)


def cell_positions(config: EnvelopeConfig) -> tuple[np.ndarray, np.ndarray]:
    """Start positions x, y [m] of every cell, flat in R_long-major order (cell (i, j) at i * n_lat + j)."""
    r_long, r_lat = grid_axes(config)
    x, y = np.meshgrid(r_long * L_SUB, r_lat * L_SUB, indexing="ij")
    return x.ravel(), y.ravel()


def starts_and_tracks(config: EnvelopeConfig, x: np.ndarray, y: np.ndarray):
    """Start states (N, 6), track-line ends (N, 2) and the feasible cells (not touching the hull)."""
    zeros = np.zeros_like(x)
    starts = np.column_stack([np.full_like(x, config.uuv_speed), zeros, zeros, x, y, zeros])
    vehicle = get_vehicle(config.vehicle)
    feasible = ~events.classify(x, y, zeros, vehicle.length, vehicle.diameter).collision
    return starts, np.column_stack([x + TRACK_AHEAD, y]), feasible


@lru_cache(maxsize=4)
def surrogate_window(vehicle: str) -> tuple[float, float] | None:
    """R_lat range where the vehicle feels the submarine: table 4.2 cut by (4.4) and (4.5), at the
    hull ratios the interaction uses (clipped to the trained range, `interaction_at`). None when
    the hull fails (4.6) or (4.7) (the NPS AUV II fails (4.6)): the blend weight is then zero at
    every position, and the residual GP never corrects the LF on that vehicle."""
    v = get_vehicle(vehicle)
    d_ratio = float(np.clip(D_SUB / v.diameter, *domain.BOUNDS[4]))
    ld_ratio = float(np.clip(v.length / v.diameter, *domain.BOUNDS[5]))
    hull_only = domain.constraint_values(np.array([[0.0, 0.08, 3.0, 0.0, d_ratio, ld_ratio]]))[0, 2:]
    if (hull_only < 0.0).any():  # (4.6), (4.7): no R_lat term
        return None
    low, high = r_lat_window(d_ratio, ld_ratio)
    return float(low), float(high)


def cached_surrogate(model: str) -> Surrogate:
    """The surrogate of a model file (empty: the shipped one), loaded once per process."""
    return load_surrogate(model or None)


@dataclass
class Envelope:
    """The outcome of every cell of one configuration (flat arrays in `cell_positions` order)."""

    config: EnvelopeConfig
    r_long: np.ndarray
    r_lat: np.ndarray
    result: BatchResult
    wall_time: float

    def summary(self) -> dict:
        """JSON-able: the configuration, the grid, every cell's outcome, counts and fractions (of
        the feasible cells: the infeasible ones start in the hull)."""
        outcome = self.result.outcome
        found = np.bincount(outcome, minlength=len(OUTCOMES))
        counts = {name: int(found[code]) for code, name in enumerate(OUTCOMES)}
        feasible = len(outcome) - counts["infeasible"]
        return {
            "config": self.config.model_dump(mode="json"),
            "label": self.config.label(),
            "cells": len(outcome),
            "feasible_cells": feasible,
            "counts": counts,
            "fractions": {name: counts[name] / feasible if feasible else 0.0 for name in OUTCOMES[:-1]},
            "r_long": self.r_long.tolist(),
            "r_lat": self.r_lat.tolist(),
            "x_m": (self.r_long * L_SUB).tolist(),  # the cell centres in metres (submarine frame)
            "y_m": (self.r_lat * L_SUB).tolist(),
            "outcome_names": list(OUTCOMES),
            "outcome": outcome.reshape(len(self.r_long), len(self.r_lat)).tolist(),
            "wall_time": round(self.wall_time, 3),
            "vehicle_steps": int(self.result.steps.sum()),
        }

    def cell_rows(self) -> list[dict]:
        """One row per cell: indices, start, outcome, closest approach of the UUV's centre to the
        hull (empty for an infeasible cell), largest cross-track error, final state and steps."""
        x, y = cell_positions(self.config)
        rows = []
        n_lat = len(self.r_lat)
        for k in range(len(x)):
            i, j = divmod(k, n_lat)
            u, v, r, fx, fy, psi = self.result.final[k]
            closest = self.result.closest[k]
            rows.append(
                {
                    "i": i,
                    "j": j,
                    "r_long": float(self.r_long[i]),
                    "r_lat": float(self.r_lat[j]),
                    "x": float(x[k]),
                    "y": float(y[k]),
                    "outcome": OUTCOMES[self.result.outcome[k]],
                    "closest": float(closest) if math.isfinite(closest) else None,
                    "max_cross_track": float(self.result.max_cross_track[k]),
                    "final_u": float(u),
                    "final_v": float(v),
                    "final_r": float(r),
                    "final_x": float(fx),
                    "final_y": float(fy),
                    "final_psi": float(psi),
                    "steps": int(self.result.steps[k]),
                }
            )
        return rows


def compute_envelope(
    config: EnvelopeConfig,
    surrogate: Surrogate | None = None,
    on_step: Callable[[int, int], None] | None = None,
) -> Envelope:
    """Run every cell of one configuration in the batch engine."""
    surrogate = surrogate or cached_surrogate(config.model)
    started = time.perf_counter()
    x, y = cell_positions(config)
    starts, ends, feasible = starts_and_tracks(config, x, y)
    template = cell_mission(config, 0.0, 0.0)
    result = run_batch(template, starts, ends, surrogate, feasible, on_step)
    r_long, r_lat = grid_axes(config)
    return Envelope(config, r_long, r_lat, result, time.perf_counter() - started)


def envelope_task(config: EnvelopeConfig) -> Envelope:
    """One configuration of a sweep (the result is about 100 kB for 800 cells)."""
    return compute_envelope(config)


def sweep(
    configs: Sequence[EnvelopeConfig],
    scheduler: str | None = None,
    workers: int | None = None,
    on_done: Callable[[int, Envelope], None] | None = None,
) -> list[Envelope]:
    """The envelopes of many configurations, in order. One configuration is one task: here in this
    process, on a running Dask cluster (`scheduler`, e.g. "tcp://10.0.0.5:8786") or on a local
    cluster of `workers` processes on loopback. Each worker loads the surrogate once (the model
    file must be readable there; the shipped model always is). `on_done(index, envelope)` follows
    the progress in completion order. A task computes exactly what this process would (the same
    functions, one BLAS thread, row-by-row arithmetic), so on workers with the same software and
    CPU family the results are identical to the bit; tests/test_envelope.py checks it."""
    results: list[Envelope | None] = [None] * len(configs)
    with task_client(workers, scheduler) as client:
        for index, envelope in completed(client, envelope_task, configs):
            results[index] = envelope
            if on_done:
                on_done(index, envelope)
    return results


def save_summary(summary: dict, path: str | Path) -> Path:
    path = Path(path)
    path.write_text(json.dumps(summary, indent=1) + "\n")
    return path


def load_summary(path: str | Path) -> dict:
    summary = json.loads(Path(path).read_text())
    if "outcome" not in summary or "config" not in summary:
        raise ValueError(f"{path}: not an envelope summary (no config or outcome grid)")
    return summary


# --- Uncertainty-aware envelopes --------------------------------------------------------------
CLOSEST_QUANTILES = (0.05, 0.5, 0.95)
SAFE_BELOW = 0.01  # P(collision) under which a cell is marked safe on the map


@dataclass(frozen=True)
class Sampling:
    """K posterior samples of the surrogate's residual delta, drawn from `seed`; with `wave_phase`
    "random" sample k also meets the waves at its own random phase."""

    samples: int
    seed: int = 0
    wave_phase: Literal["fixed", "random"] = "fixed"
    features: int = DEFAULT_FEATURES

    def __post_init__(self):
        if self.samples < 1:
            raise ValueError(f"--samples wants at least 1, got {self.samples}")
        if self.seed < 0:
            raise ValueError(f"--sample-seed wants 0 or more, got {self.seed}")
        if self.wave_phase not in ("fixed", "random"):
            raise ValueError(f"--wave-phase wants fixed or random, got {self.wave_phase!r}")


def wave_time_offsets(config: EnvelopeConfig, sampling: Sampling) -> np.ndarray | None:
    """(K,) clock offsets [s] that give each sample a uniform random wave phase, or None (fixed
    phase, or calm water). The phase a UUV meets is k xi - omega t with xi = x + U_sub t along the
    waves' heading (0 in an envelope), so a clock offset t0 shifts it by (k U_sub - omega) t0."""
    state = waves.sea_state(config.sea_state)
    if sampling.wave_phase == "fixed" or state.amplitude == 0.0:
        return None
    rate = state.omega - state.wavenumber * config.u_sub
    phase = np.random.default_rng([sampling.seed, 1]).uniform(0.0, 2.0 * math.pi, sampling.samples)
    return phase / rate


@dataclass
class SampledEnvelope:
    """Every cell flown under samples `members` of `sampling`; `result` holds one row per
    (sample, cell), sample-major (row m * cells + cell)."""

    config: EnvelopeConfig
    sampling: Sampling
    r_long: np.ndarray
    r_lat: np.ndarray
    members: np.ndarray
    result: BatchResult
    wall_time: float

    def probabilities(self) -> np.ndarray:
        """(cells, 5) share of the samples ending in each outcome (OUTCOMES order)."""
        outcome = self.result.outcome.reshape(len(self.members), -1)
        return np.stack([(outcome == code).mean(axis=0) for code in range(len(OUTCOMES))], axis=-1)

    def closest_quantiles(self) -> np.ndarray:
        """(cells, 3) CLOSEST_QUANTILES of the closest approach [m] over the samples (inf: infeasible)."""
        closest = self.result.closest.reshape(len(self.members), -1)
        with np.errstate(invalid="ignore"):
            return np.quantile(closest, CLOSEST_QUANTILES, axis=0).T

    def summary(self) -> dict:
        """JSON-able: configuration, sampling, grid, per-cell outcome probabilities, closest-approach
        quantiles, the cells marked safe (P(collision) < SAFE_BELOW) and the expected fractions of
        the feasible cells."""
        n_long, n_lat = len(self.r_long), len(self.r_lat)
        p = self.probabilities()
        feasible = p[:, OUTCOMES.index("infeasible")] < 1.0
        quantiles = self.closest_quantiles()
        grid = lambda values: values.reshape(n_long, n_lat).tolist()  # noqa: E731
        return {
            "config": self.config.model_dump(mode="json"),
            "label": self.config.label(),
            "sampling": {
                "samples": self.sampling.samples,
                "seed": self.sampling.seed,
                "wave_phase": self.sampling.wave_phase,
                "features": self.sampling.features,
            },
            "cells": len(p),
            "feasible_cells": int(feasible.sum()),
            "r_long": self.r_long.tolist(),
            "r_lat": self.r_lat.tolist(),
            "x_m": (self.r_long * L_SUB).tolist(),  # the cell centres in metres (submarine frame)
            "y_m": (self.r_lat * L_SUB).tolist(),
            "outcome_names": list(OUTCOMES),
            "probability": {name: grid(p[:, code]) for code, name in enumerate(OUTCOMES)},
            "expected_fractions": {
                name: float(p[feasible, code].mean()) if feasible.any() else 0.0
                for code, name in enumerate(OUTCOMES[:-1])
            },
            "safe_below": SAFE_BELOW,
            "marked_safe": grid(feasible & (p[:, OUTCOMES.index("collision")] < SAFE_BELOW)),
            "closest_quantiles": list(CLOSEST_QUANTILES),
            "closest": [grid(np.where(np.isfinite(q), q, np.nan)) for q in quantiles.T],
            "wall_time": round(self.wall_time, 3),
            "vehicle_steps": int(self.result.steps.sum()),
        }

    def cell_rows(self) -> list[dict]:
        """One row per cell: indices, start, the probability of each outcome and the closest-approach
        quantiles (empty for an infeasible cell)."""
        x, y = cell_positions(self.config)
        p, quantiles = self.probabilities(), self.closest_quantiles()
        rows = []
        for k in range(len(x)):
            i, j = divmod(k, len(self.r_lat))
            row = {"i": i, "j": j, "r_long": float(self.r_long[i]), "r_lat": float(self.r_lat[j])}
            row |= {"x": float(x[k]), "y": float(y[k])}
            row |= {f"p_{name}": float(p[k, code]) for code, name in enumerate(OUTCOMES)}
            for q, value in zip(CLOSEST_QUANTILES, quantiles[k], strict=True):
                row[f"closest_q{round(100 * q):02d}"] = float(value) if math.isfinite(value) else None
            rows.append(row)
        return rows


def sampled_task(item: tuple[EnvelopeConfig, Sampling, np.ndarray]) -> SampledEnvelope:
    """Some samples of one configuration (a Dask task of `sampled_envelope`)."""
    config, sampling, members = item
    return compute_sampled(config, sampling, members)


def compute_sampled(
    config: EnvelopeConfig,
    sampling: Sampling,
    members: np.ndarray | None = None,
    surrogate: Surrogate | None = None,
    on_step: Callable[[int, int], None] | None = None,
    on_delta: Callable[[np.ndarray, np.ndarray], None] | None = None,
) -> SampledEnvelope:
    """Every cell under the samples `members` (default: all) as one batch in the batch engine: the
    UUV of (sample k, cell) sees sample k's delta wherever the mean envelope uses the mean. All K
    samples are drawn (from the seed) whatever `members` is, so a split over workers flies the
    same fields. `on_delta(x_c, rows)` sees every query of delta (the envelope design's record
    of where the trajectories ask it; rows index the batch, sample-major)."""
    surrogate = surrogate or cached_surrogate(config.model)
    started = time.perf_counter()
    members = np.arange(sampling.samples) if members is None else np.asarray(members, dtype=int)
    samples = draw_samples(surrogate, sampling.samples, sampling.seed, sampling.features)
    x, y = cell_positions(config)
    starts, ends, feasible = starts_and_tracks(config, x, y)
    member = np.repeat(members, len(x))  # the sample of each batch row
    offsets = wave_time_offsets(config, sampling)

    def sampled_delta(X: np.ndarray, uuvs: np.ndarray) -> np.ndarray:
        if on_delta is not None:
            on_delta(X, uuvs)
        return samples.rows(X, member[uuvs])

    result = run_batch(
        cell_mission(config, 0.0, 0.0),
        np.tile(starts, (len(members), 1)),
        np.tile(ends, (len(members), 1)),
        surrogate,
        np.tile(feasible, len(members)),
        on_step,
        delta=sampled_delta,
        time_offset=None if offsets is None else offsets[member],
    )
    r_long, r_lat = grid_axes(config)
    return SampledEnvelope(config, sampling, r_long, r_lat, members, result, time.perf_counter() - started)


def sampled_envelope(
    config: EnvelopeConfig,
    sampling: Sampling,
    scheduler: str | None = None,
    workers: int | None = None,
    on_step: Callable[[int, int], None] | None = None,
) -> SampledEnvelope:
    """The uncertainty-aware envelope of one configuration: in this process (`on_step` follows the
    steps), or with the samples split into one task per worker on a Dask cluster (`scheduler`, or
    a local one of `workers` processes). Row-by-row arithmetic makes the two agree bit for bit."""
    started = time.perf_counter()
    with task_client(workers, scheduler) as client:
        if client is None:
            return compute_sampled(config, sampling, on_step=on_step)
        chunks = np.array_split(np.arange(sampling.samples), min(sampling.samples, len(client.nthreads())))
        parts: list[SampledEnvelope | None] = [None] * len(chunks)
        for index, part in completed(client, sampled_task, [(config, sampling, c) for c in chunks]):
            parts[index] = part
    joined = BatchResult(
        *(np.concatenate([getattr(p.result, f) for p in parts]) for f in BatchResult.__dataclass_fields__)
    )
    first = parts[0]
    return SampledEnvelope(
        config, sampling, first.r_long, first.r_lat, np.arange(sampling.samples), joined, time.perf_counter() - started
    )


# --- The thesis's envelope figures -------------------------------------------------------------
SIZES = ("remus100", "nps_auv_ii", "sdv")  # small, medium, large (thesis section 5.9)


@dataclass(frozen=True)
class ThesisFigure:
    """One envelope figure of the thesis: its panels, each (caption, configuration), and how
    they are laid out (columns compare, rows list)."""

    number: str
    title: str
    panels: tuple[tuple[str, EnvelopeConfig], ...]
    columns: int = 1


def _sizes(**settings) -> tuple[tuple[str, EnvelopeConfig], ...]:
    names = {"remus100": "small (REMUS 100)", "nps_auv_ii": "medium (NPS AUV II)", "sdv": "large (SDV)"}
    return tuple((names[v], EnvelopeConfig(vehicle=v, **settings)) for v in SIZES)


def _with_and_without(**settings) -> tuple[tuple[str, EnvelopeConfig], ...]:
    panels = []
    for (caption, plain), (_, compensated) in zip(
        _sizes(**settings), _sizes(behaviour="nuv_compensation", **settings), strict=True
    ):
        panels += [(f"{caption}, waypoints", plain), (f"{caption}, N_uv compensation", compensated)]
    return tuple(panels)


def thesis_figures() -> list[ThesisFigure]:
    """Figures 5-10 to 5-14 and 6-7 to 6-11 (U_sub = 1.5 m/s, U_ot = 0, d_lead = 3 L_uuv unless
    the figure varies it; sea state 0 means no waves)."""
    small = "remus100"
    return [
        ThesisFigure("5-10", "Standard waypoints, no waves", _sizes()),
        ThesisFigure(
            "5-11",
            "Impact of d_lead, small UUV, no waves",
            tuple((f"d_lead = {k} L_uuv", EnvelopeConfig(vehicle=small, d_lead=k)) for k in (1.0, 3.0, 5.0)),
        ),
        ThesisFigure("5-12", "Sea state 6 at 50 m", _sizes(sea_state=6, depth=50.0)),
        ThesisFigure("5-13", "Sea state 6 at 90 m", _sizes(sea_state=6, depth=90.0)),
        ThesisFigure("5-14", "Sea state 5 at 50 m", _sizes(sea_state=5, depth=50.0)),
        ThesisFigure("6-7", "With and without N_uv compensation, no waves", _with_and_without(), columns=2),
        ThesisFigure(
            "6-8",
            "Impact of gamma on N_uv compensation, small UUV, no waves",
            tuple(
                (f"gamma = {g:g}", EnvelopeConfig(vehicle=small, behaviour="nuv_compensation", gamma=g))
                for g in (1.0, 5.0, 10.0)
            ),
        ),
        ThesisFigure("6-9", "N_uv compensation, sea state 5 at 50 m", _with_and_without(sea_state=5, depth=50.0), 2),
        ThesisFigure("6-10", "N_uv compensation, sea state 6 at 90 m", _with_and_without(sea_state=6, depth=90.0), 2),
        ThesisFigure("6-11", "N_uv compensation, sea state 6 at 50 m", _with_and_without(sea_state=6, depth=50.0), 2),
    ]


def unique_configs(figures: Iterable[ThesisFigure], **overrides) -> list[EnvelopeConfig]:
    """The distinct configurations of some figures (figures share some), with settings overridden
    (a smaller grid for a quick look, say)."""
    seen: dict[EnvelopeConfig, None] = {}
    for figure in figures:
        for _, config in figure.panels:
            seen.setdefault(config.model_copy(update=overrides) if overrides else config, None)
    return list(seen)
