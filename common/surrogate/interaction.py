"""Interaction forces for the sim and the helm: surrogate predictions at the vehicle's state,
turned into dimensional forces with a blend weight (thesis (5.20); docs/design.md, "Physics
decisions").

Replace and thesis modes, and the increment mode of a model without the LF in the loop: the
weight is 1 well inside the surrogate's domain (table 4.2 bounds and constraints (4.4)-(4.7)) and
falls smoothly to 0 across a band inside its boundary, heading included, so the dynamics move from
(5.20) to (5.10) without a force jump (`dynamics.Interaction`).

Increment mode with the LF in the loop (a model of kind "lf_in_loop", the default): the increment
added to (5.11) is [LF(x) - LF_free(x)] + w(x) [delta(x_c) - (HF_free(x_c) - LF_free(x_c))]
(`lf_in_loop_increment`). The exact low fidelity (`hydro.low_fidelity`) carries the heading and
distance dependence at the true pose x, at any heading; the residual GP delta corrects it at x_c,
x clamped into where it was trained, less its free-stream part (the two models' difference for
the UUV alone, no interaction), with a weight w of position, speed and the constraints that never
depends on the heading. Where a viscous correction was fitted for the model (`viscous`: a GP of
RANS's interaction at the RANS stations), it takes the increment towards RANS near them. The
LF runs here, in the process that needs the force (the sim, the helm, the batch engine): it
costs well under a millisecond, and computing it where it is used keeps one code path for
in-process, multi-process and batch runs, so they agree bit for bit; the surrogate server
answers only delta (`discrepancy`).

A force model is anything with `predict(inputs) -> surrogate.Prediction` (and, for the LF in the
loop, `kind` and `discrepancy`): the in-process `surrogate.Surrogate`, or
`apps.services.RemoteSurrogate`, which asks the surrogate server over the bus. Both compute the
same numbers. The server is asked about delta before the LF is evaluated and answered after it
(`discrepancy_later`), so its round trip overlaps the LF's work.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from nearsub.common.hydro import low_fidelity as hydro_lf
from nearsub.common.physics import proximity
from nearsub.common.physics.dynamics import PSI, Interaction, U, X, Y
from nearsub.common.physics.hull import R_SUB
from nearsub.common.physics.vehicles import Vehicle
from nearsub.common.surrogate import domain
from nearsub.common.surrogate import free_stream as fs
from nearsub.common.surrogate import interaction_kernel as kernel
from nearsub.common.surrogate import query as sg
from nearsub.common.surrogate import viscous as vc
from nearsub.common.surrogate.query import ServiceError

# Width of the ramp inside each bound, as a fraction of the input's range (table 4.2): 0.08 deg of
# the +/-2 deg heading range, 2.5 m of R_long, 0.06 kn of speed. nearsub's choice.
BLEND_FRACTION = 0.02
# Width of the ramp inside each constraint (4.4)-(4.7), in the units of `constraint_values`:
# (4.4), (4.5) change by 0.0965 per metre of lateral distance (8.575 / L_sub), so 0.005 is about
# 5 cm; (4.6), (4.7) are in L/D_uuv. Narrow, because (4.4) (a 5 cm clearance) and (4.5) (at most
# 2 D_uuv off the hull, where the thesis says the interaction has died out) leave a lateral window
# of 0.26 m for the REMUS 100 and 0.7 m for the SDV. nearsub's choice.
CONSTRAINT_BAND = np.array([0.005, 0.005, 0.1, 0.1])
GEOMETRY = slice(4, 6)  # D_sub/D_uuv and L/D_uuv: fixed for a vehicle
# Their trained range (table 4.2), which `interaction_at` clips them to (as np.clip: neither bound is 0).
_GEOMETRY_LOWER, _GEOMETRY_UPPER = domain.BOUNDS[GEOMETRY, 0].copy(), domain.BOUNDS[GEOMETRY, 1].copy()
_UNCLIPPED = (np.full(2, -np.inf), np.full(2, np.inf))
# The discrepancy weight of the LF-in-the-loop increment across (4.5): 1 up to the edge, falling
# (smoothstep) to 0 one UUV diameter of clearance beyond it, with delta held at its value on the
# edge meanwhile. A ramp inside the 0.26-0.7 m window (CONSTRAINT_BAND, about 5 cm) would take
# the correction away where it was trained and change the applied increment steeply where HF and
# LF disagree (Y' at the shoulders, docs/hydro/sweeps). nearsub's choice.
DELTA_TAPER = 1.0  # [D_uuv]
# Reach of the LF increment, in clearance of the UUV's CB from the submarine's outline
# (`proximity.hull_signed_distance`): in full up to LF_FULL, then cut off smoothly (smoothstep) to
# zero at LF_CUT. nearsub's choice: LF_FULL is where the increment has fallen below LF_FRACTION of
# the vehicle's own forces for all three library vehicles at 2 and 5 kn (table 4.2's speeds),
# psi = 0, anywhere round the hull: |X'|, |Y'| below 1 % of its drag X_u|u| u^2 and |N'| below 1 %
# of its Munk moment N_uv u^2 sin(2 deg) cos(2 deg) (the heading bound of table 4.2). N' sets the
# distance (the NPS AUV II, whose N_uv is small, reaches 1 % at about 200 m; X' and Y' by 40 m);
# docs/design.md, "Hydrodynamic fidelities", has the figures and `tests/test_lf_in_loop.py` checks
# it. The LF's field table (`low_fidelity.R_FIELD_MAX`) reaches LF_CUT plus R_sub plus a UUV's
# length (`LF_MAX_LENGTH`, above every library vehicle).
LF_FRACTION = 0.01
LF_FULL = 210.0  # [m]
LF_CUT = 260.0  # [m]
LF_MAX_LENGTH = hydro_lf.R_FIELD_MAX - R_SUB - LF_CUT  # longest UUV whose strips stay in the table [m]


class IncrementError(ServiceError):
    """The "increment" mode has no free-stream table made for the surrogate it is given."""


class ForceModel(Protocol):
    kind: str  # "lf_in_loop", "multi_fidelity" or "gp"
    model_id: str | None  # the model's content hash (the server's model: from its first reply)

    def predict(self, inputs: np.ndarray, return_std: bool = True) -> sg.Prediction: ...

    def discrepancy(self, inputs: np.ndarray, return_std: bool = True) -> tuple[np.ndarray, np.ndarray | None]: ...


# Table 4.2's bounds and the ramps' widths inside them, as the kernels read them.
_LOWER, _UPPER = np.ascontiguousarray(domain.BOUNDS[:, 0]), np.ascontiguousarray(domain.BOUNDS[:, 1])
_RAMP = BLEND_FRACTION * (_UPPER - _LOWER)
LATERAL_SLOPE = 8.575  # (4.5) falls by 8.575 (= L_sub / D_sub) per unit of R_lat


def _rows(inputs: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.atleast_2d(np.asarray(inputs, dtype=float)))


def blend_weight(inputs: np.ndarray, heading: bool = True) -> np.ndarray:
    """(n,) weight of the surrogate's forces at inputs (n, 6): 1 well inside table 4.2's bounds
    and the constraints (4.4)-(4.7), 0 outside, smoothstep across a ramp BLEND_FRACTION of each
    state input's range (position, speed and, with `heading`, the heading) or CONSTRAINT_BAND of
    each constraint inside them. The hull ratios are constants of a vehicle, so they switch the
    surrogate on or off for a whole mission (see `interaction_at`). (4.4)-(4.7) hold no heading term
    (docs/design.md, "Thesis errata": (4.4) has 0.27 sin(2 deg) as a constant), so without
    `heading` it does not depend on psi at all."""
    X = _rows(inputs)
    out = np.empty(len(X))
    kernel.weight_rows(X, domain.CONSTRAINT_COEFFICIENTS, _LOWER, _UPPER, _RAMP, CONSTRAINT_BAND, heading, 0.0, out)
    return out


def discrepancy_weight(inputs: np.ndarray) -> np.ndarray:
    """(n,) weight w of delta in the LF-in-the-loop increment: `blend_weight` without its heading
    ramp, and across (4.5) the outward ramp of DELTA_TAPER instead of the inward one."""
    X = _rows(inputs)
    out = np.empty(len(X))
    kernel.weight_rows(
        X, domain.CONSTRAINT_COEFFICIENTS, _LOWER, _UPPER, _RAMP, CONSTRAINT_BAND, False, DELTA_TAPER, out
    )
    return out


def discrepancy_inputs(inputs: np.ndarray) -> np.ndarray:
    """x_c: inputs (n, 6) clamped into table 4.2's box and then, beyond (4.5), R_lat onto its edge
    (where `discrepancy_weight` tapers delta off), so delta is asked only where it was trained."""
    X = _rows(inputs)
    out = np.empty_like(X)
    kernel.clamped_rows(X, domain.CONSTRAINT_COEFFICIENTS, _LOWER, _UPPER, LATERAL_SLOPE, out)
    return out


def prepare(mode: str) -> None:
    """Tabulate the LF's submarine field now (a few seconds, once per process) when `mode` may put
    the LF in the loop, so that an app's first step does not pay for it within the step timeout."""
    if mode == "increment":
        hydro_lf.submarine_field()


def lf_reach_weight(x: np.ndarray, y: np.ndarray, clearance: np.ndarray | None = None) -> np.ndarray:
    """(n,) weight of the LF increment at CB positions x, y [m] (submarine frame): 1 up to LF_FULL
    of clearance from the hull, 0 beyond LF_CUT, smooth between (smoothstep), 0 for a non-finite
    state. Independent of the heading. `clearance`: `proximity.hull_signed_distance(x, y)`, if
    already known."""
    if clearance is None:
        clearance = proximity.hull_signed_distance(x, y)
    clearance = np.ascontiguousarray(np.ravel(np.asarray(clearance, dtype=float)))
    out = np.empty(len(clearance))
    kernel.reach_rows(clearance, LF_FULL, LF_CUT, out)
    return out


FLAG_NAMES = domain.INPUT_NAMES + domain.CONSTRAINT_NAMES  # columns of InteractionAt.outside_mask


@dataclass(frozen=True)
class InteractionAt:
    """The surrogate's view of one or more vehicle states, (n, ...) arrays.

    `interaction` is what the dynamics use: forces and weight (shaped as the state). `forces` are
    those forces before the weight, `applied` = weight x forces, the surrogate's share of the
    (5.11)/(5.20) right-hand side (in "increment" mode exactly what is added to (5.11); in
    "replace"/"thesis" the (5.10) terms it stands for enter with 1 - weight). `model` and `std` are
    the model's raw answer and its std: the discrepancy delta(x_c) in the LF-in-the-loop increment
    (NaN where its weight is zero: not asked), the prediction otherwise; `lf` the LF increment
    LF(x) - LF_free(x) (NaN when the mode does not use it); `delta_free` the free-stream part of
    delta, HF_free(x_c) - LF_free(x_c), which the increment leaves out (NaN likewise, and where
    delta is not asked); `delta_weight` the weight of delta (NaN likewise), `viscous` the viscous
    correction's change (zero without one), so forces = lf + delta_weight (model - delta_free) +
    viscous, the middle term zero where delta_weight is. All in N and N m,
    frame convention. `outside_mask` (n, 10) says which inputs (table 4.2) and constraints
    (4.4)-(4.7) the state is outside of (`outside`), `lf_held` where the LF held its field at the
    table's inner edge (the UUV within 1 cm of the submarine's widest radius, `low_fidelity`)."""

    interaction: Interaction
    forces: np.ndarray
    applied: np.ndarray
    model: np.ndarray
    std: np.ndarray
    lf: np.ndarray
    delta_free: np.ndarray
    delta_weight: np.ndarray
    viscous: np.ndarray
    in_domain: np.ndarray
    constraints_ok: np.ndarray
    outside_mask: np.ndarray
    lf_held: np.ndarray

    def outside(self, row: int = 0) -> list[str]:
        """Names of the inputs and constraints that state `row` is outside of ([] inside)."""
        return [name for name, out in zip(FLAG_NAMES, self.outside_mask[row], strict=True) if out]


def outside_mask(raw: np.ndarray) -> np.ndarray:
    """(n, 10) True where a raw input lies outside table 4.2's bounds (non-finite included) or a
    constraint (4.4)-(4.7) fails, columns FLAG_NAMES."""
    X = _rows(raw)
    out = np.empty((len(X), len(FLAG_NAMES)), dtype=bool)
    kernel.flag_rows(X, domain.CONSTRAINT_COEFFICIENTS, _LOWER, _UPPER, out)
    return out


HULL_SHAPE_CONSTRAINTS = [2, 3]  # (4.6) and (4.7): functions of the hull ratios alone


def geometry_outside(vehicle: Vehicle) -> str | None:
    """Why the vehicle's hull is outside the surrogate's trained hulls (table 4.2, or the hull-shape
    constraints (4.6)/(4.7), which switch the surrogate's share off everywhere), or None."""
    inputs, _ = domain.to_inputs(0.0, 0.0, 0.0, 0.0, vehicle.length, vehicle.diameter)
    lower, upper = domain.BOUNDS[GEOMETRY, 0], domain.BOUNDS[GEOMETRY, 1]
    inputs[:, GEOMETRY] = np.clip(inputs[:, GEOMETRY], lower, upper)  # as interaction_at evaluates it
    shape = domain.constraint_values(inputs)[0, HULL_SHAPE_CONSTRAINTS]
    if np.any(shape < 0):
        names = [domain.CONSTRAINT_NAMES[i] for i in HULL_SHAPE_CONSTRAINTS]
        failed = ", ".join(f"{n} = {v:.3g} < 0" for n, v in zip(names, shape, strict=True) if v < 0)
        return (
            f"vehicle {vehicle.name}: hull outside the surrogate's constraints ({failed}); the surrogate's "
            "share is zero everywhere for this vehicle (with the LF in the loop in increment mode the LF "
            "increment still acts; in replace and thesis modes there is no interaction)"
        )
    inputs, _ = domain.to_inputs(0.0, 0.0, 0.0, 0.0, vehicle.length, vehicle.diameter)
    values = inputs[0, GEOMETRY]
    if np.all((values >= lower) & (values <= upper)):
        return None
    names = domain.INPUT_NAMES[GEOMETRY]
    parts = [f"{n} = {v:.3g} (trained {lo:g}-{hi:g})" for n, v, lo, hi in zip(names, values, lower, upper, strict=True)]
    return (
        f"vehicle {vehicle.name}: " + ", ".join(parts) + "; the surrogate is evaluated at the nearest trained "
        "hull (the thesis's own small UUV, REMUS 100 at D_sub/D_uuv = 54.5, lies outside table 4.2 too)"
    )


_TABLES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # force model -> its free-stream table


def increment_table(model: ForceModel) -> fs.FreeStreamTable:
    """The free-stream table made for this model (cached per model object); raises IncrementError,
    naming the mission field and the model file, when there is none: adding the surrogate's total
    forces (which hold the UUV's own drag and Munk moment) on top of (5.11) would count them twice."""
    try:
        return _TABLES[model]
    except (KeyError, TypeError):
        pass
    model_id = getattr(model, "model_id", None)
    loaded = getattr(model, "loaded", None)
    path = getattr(loaded, "path", None)
    try:
        table, searched = fs.find_table(model_id, path)
    except fs.FreeStreamFileError as exc:
        raise IncrementError(f'apps.sim.interaction = "increment": {exc}') from None
    if table is None:
        source = getattr(model, "source", None) or path or "of the surrogate server (surrogate.model)"
        raise IncrementError(
            f'apps.sim.interaction = "increment" needs the free-stream value of the hydrodynamic model that '
            f"the model {source} (model id {model_id}) was trained on, and no free-stream table matches "
            f"that model (looked at {', '.join(str(p) for p in searched)}). Use the shipped model "
            "(surrogate.model empty), build the table of a model trained on common/hydro/high_fidelity.py with "
            '"python -m nearsub.tools.free_stream MODEL", or set apps.sim.interaction = "replace".'
        )
    try:
        _TABLES[model] = table
    except TypeError:  # a model object without weak references: look it up every call
        pass
    return table


_CORRECTIONS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # force model -> its correction or None


def viscous_correction(model: ForceModel) -> vc.ViscousCorrection | None:
    """The viscous correction fitted for this model (`viscous.find`, cached per model object), or
    None: a model without one flies the increment as it is. A correction file that cannot be read
    raises IncrementError, naming it."""
    try:
        return _CORRECTIONS[model]
    except (KeyError, TypeError):
        pass
    path = getattr(getattr(model, "loaded", None), "path", None)
    try:
        found = vc.find(getattr(model, "model_id", None), path)
    except vc.CorrectionFileError as exc:
        raise IncrementError(
            f"surrogate.viscous = true: {exc} (set surrogate.viscous = false to fly without it)"
        ) from None
    try:
        _CORRECTIONS[model] = found
    except TypeError:
        pass
    return found


@dataclass(frozen=True)
class DomainRows:
    """What the domain says of rows of raw inputs (n, 6), in one pass of the kernel
    (`interaction_kernel.interaction_rows`): `inputs`, the rows with the hull ratios clipped to
    their trained range, and for those, with the LF in the loop, the discrepancy weight and x_c
    (`discrepancy_weight`, `discrepancy_inputs`; `weight` NaN), otherwise the blend weight
    (`blend_weight`; `delta_weight` and `clamped` NaN); `flags`, the raw rows' `outside_mask`."""

    inputs: np.ndarray
    weight: np.ndarray
    delta_weight: np.ndarray
    clamped: np.ndarray
    flags: np.ndarray

    @classmethod
    def of(cls, raw: np.ndarray, lf_in_loop: bool, clip: bool = True) -> DomainRows:
        """The rows' terms; without `clip` the hull ratios are taken as they are."""
        raw = _rows(raw)
        lower, upper = (_GEOMETRY_LOWER, _GEOMETRY_UPPER) if clip else _UNCLIPPED
        n = len(raw)
        inputs, clamped = np.empty_like(raw), np.empty_like(raw)
        weight, delta_weight = np.empty(n), np.empty(n)
        flags = np.empty((n, len(FLAG_NAMES)), dtype=bool)
        kernel.interaction_rows(
            raw, domain.CONSTRAINT_COEFFICIENTS, _LOWER, _UPPER, _RAMP, CONSTRAINT_BAND, lower, upper, LATERAL_SLOPE,
            DELTA_TAPER, lf_in_loop, inputs, weight, delta_weight, clamped, flags,
        )  # fmt: skip
        return cls(inputs, weight, delta_weight, clamped, flags)


def interaction_at(
    model: ForceModel,
    state: np.ndarray,
    vehicle: Vehicle,
    rho: float,
    mode: str,
    with_std: bool = True,
    weighted_only: bool = False,
    free_stream: fs.FreeStreamTable | None = None,
    delta: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    viscous: bool = True,
) -> InteractionAt:
    """Ask the force model about the state(s) (6,) or (n, 6) and build the dynamics' input. The
    fields are (n, 3) and (n,) arrays; `interaction` has the shape of `state` ((3,) and () for one
    vehicle), as the dynamics want.

    The hull ratios are clipped to the trained range (`geometry_outside` says when, and the sim
    reports it once): they are constants of the vehicle, so clipping them moves the whole mission
    to the nearest trained hull instead of switching the interaction off everywhere. Without
    `with_std` the std is NaN (sweeps do not need it; the mean is the same either way). In
    "replace", "thesis" and the increment of a model without the LF in the loop, with
    `weighted_only` the model is asked only about the states whose weight is above zero, and the
    others get zero forces: the dynamics multiply them by that zero weight, so the motion is the
    same (to the sign of a zero), and a sweep where most UUVs are outside the domain is cheap. The
    LF-in-the-loop increment always asks about delta only where its weight is above zero.

    "increment" with a model of kind "lf_in_loop": `lf_in_loop_increment`, with the HF free stream
    from `free_stream` or the table made for the model (`increment_table`). "increment" with another
    model: the prediction minus that free-stream value at the same clipped inputs, with the blend
    weight; "replace" and "thesis": the prediction with the blend weight. `delta(x_c, rows)`, for
    the LF-in-the-loop increment only, replaces the model's mean of delta at the rows `rows` of
    `state` (a posterior function sample, `sampling.PosteriorSamples.rows`); its std is NaN. With
    `viscous`, the LF-in-the-loop increment adds the model's viscous correction if it has one
    (`viscous_correction`); the other modes never do."""
    single = np.ndim(state) == 1
    state = np.atleast_2d(state)
    u, x, y, psi = state[:, U], state[:, X], state[:, Y], state[:, PSI]
    raw, mirror = domain.to_inputs(x, y, u, psi, vehicle.length, vehicle.diameter)
    lf_in_loop = mode == "increment" and getattr(model, "kind", None) == "lf_in_loop"
    rows = DomainRows.of(raw, lf_in_loop)
    inputs, n = rows.inputs, len(raw)
    table = None
    if mode == "increment":
        table = free_stream if free_stream is not None else increment_table(model)
    if lf_in_loop:
        correction = viscous_correction(model) if viscous else None
        coefficients, weight, model_mean, spread, lf, delta_free, delta_weight, held, rans = lf_in_loop_increment(
            model, inputs, x, y, vehicle, table, with_std, delta, rows, correction
        )
    elif delta is not None:
        raise ValueError(f'a sampled delta needs the "increment" mode and a model of kind "lf_in_loop", got {mode!r}')
    else:
        weight = rows.weight
        asked = weight > 0.0 if weighted_only else np.ones(n, dtype=bool)
        model_mean, spread = np.zeros((n, 3)), np.full((n, 3), np.nan)
        free = np.zeros((n, 3))
        if asked.any():
            prediction = model.predict(inputs[asked], return_std=with_std)
            model_mean[asked] = prediction.mean
            if table is not None:
                free[asked] = table.coefficients(inputs[asked])
            if with_std:
                spread[asked] = prediction.std
        coefficients = model_mean - free
        lf, delta_free = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
        delta_weight, held = rows.delta_weight, np.zeros(n, dtype=bool)
        rans = np.zeros((n, 3))
    # One conversion for the six (n, 3) arrays (element-wise, so each gets its own bits).
    parts = np.ascontiguousarray(np.stack([coefficients, model_mean, spread, lf, delta_free, rans]))
    converted = np.empty_like(parts)
    kernel.force_rows(parts, mirror, np.ascontiguousarray(u), np.full(n, float(vehicle.length)), float(rho), converted)
    forces, model_forces, spread_forces, lf_forces, free_forces, rans_forces = converted
    safe = np.where(np.isfinite(forces), forces, 0.0)  # weight is 0 wherever they are not finite
    interaction = Interaction(safe[0], weight[0], mode) if single else Interaction(safe, weight, mode)
    flags = rows.flags
    return InteractionAt(
        interaction=interaction,
        forces=forces,
        applied=weight[:, None] * safe,
        model=model_forces,
        std=np.abs(spread_forces),
        lf=lf_forces,
        delta_free=free_forces,
        delta_weight=delta_weight,
        viscous=rans_forces,
        in_domain=~flags[:, : len(domain.INPUT_NAMES)].any(axis=1),
        constraints_ok=~flags[:, len(domain.INPUT_NAMES) :].any(axis=1),
        outside_mask=flags,
        lf_held=held,
    )


def discrepancy_later(
    model: ForceModel, inputs: np.ndarray, with_std: bool
) -> Callable[[], tuple[np.ndarray, np.ndarray | None]]:
    """Ask about delta at inputs now and take the answer when it is needed: the surrogate server
    (`apps.services.RemoteSurrogate.discrepancy_later`) predicts while the asker computes the LF;
    an in-process model answers at once. The same numbers either way."""
    later = getattr(model, "discrepancy_later", None)
    if later is not None:
        return later(inputs, return_std=with_std)
    found = model.discrepancy(inputs, return_std=with_std)
    return lambda: found


def lf_in_loop_increment(
    model: ForceModel,
    inputs: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    vehicle: Vehicle,
    free_stream: fs.FreeStreamTable,
    with_std: bool = True,
    delta: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    rows: DomainRows | None = None,
    viscous: vc.ViscousCorrection | None = None,
):
    """The increment [LF(x) - LF_free(x)] + w(x) [delta(x_c) - (HF_free(x_c) - LF_free(x_c))] in
    coefficients (n, 3) at inputs (n, 6) (hull ratios clipped) of UUVs at CB positions x, y, with
    the dynamics' weight (the LF's reach, `lf_reach_weight`), and the parts: delta's mean and std
    (n, 3) at x_c, the LF increment (n, 3), delta's free-stream part (n, 3), w (n,) and where the
    LF held its field (n,) (`low_fidelity.lf_increment_terms`), and the viscous correction's mean
    change (n, 3), already in the increment (zeros without `viscous`; `viscous.ViscousCorrection`).

    delta is the GP of HF - LF of the total coefficients, so it holds HF_free - LF_free, the two
    models' difference for the UUV alone, which is no interaction: it is taken out with the HF's
    free stream `free_stream` (the model's free-stream table, `surrogate.free_stream`) and the LF's own
    (`low_fidelity.lf_free_stream`) at x_c. x_c and w: `discrepancy_inputs`, `discrepancy_weight`;
    w ignores the heading, so the LF alone carries it beyond +/-2 deg, continuously. LF_free is the
    same model's lone UUV at the same hull, speed and heading, so the increment tends to zero away
    from the submarine. delta is asked only where both weights are above zero: elsewhere it
    would be multiplied by zero, and its mean, std and free-stream part are NaN (not asked). A UUV
    beyond (4.5) or outside table 4.2's speeds costs the surrogate server nothing. `delta`: as in
    `interaction_at`; `rows`: the inputs' `DomainRows` with the LF in the loop, if already known."""
    if vehicle.length > LF_MAX_LENGTH:
        raise ValueError(
            f"vehicle {vehicle.name}: {vehicle.length:g} m long, longer than the {LF_MAX_LENGTH:.2f} m the LF's "
            f"field table serves at the increment's cut-off ({LF_CUT:g} m from the hull)"
        )
    n = len(inputs)
    clearance = proximity.hull_signed_distance(x, y)  # the LF's reach and the viscous correction's input
    reach = lf_reach_weight(x, y, clearance)
    if rows is None:
        rows = DomainRows.of(inputs, lf_in_loop=True, clip=False)
    delta_weight = rows.delta_weight
    near = reach > 0.0
    asked = near & (delta_weight > 0.0)  # delta is asked only where it counts
    # Every row (the sim's one vehicle in the trained window, a batch near the hull) needs no masked copies.
    every_asked, every_near = n > 0 and bool(asked.all()), n > 0 and bool(near.all())
    if any_asked := every_asked or asked.any():
        clamped = rows.clamped if every_asked else rows.clamped[asked]
        if delta is None:  # asked first, answered after the LF below (`discrepancy_later`)
            answer = discrepancy_later(model, clamped, with_std)
    if every_near:
        with_sub, alone, held = hydro_lf.lf_increment_terms(inputs)
        lf = with_sub - alone
    else:
        lf, held = np.zeros((n, 3)), np.zeros(n, dtype=bool)
        if near.any():
            with_sub, alone, held[near] = hydro_lf.lf_increment_terms(inputs[near])
            lf[near] = with_sub - alone
    if any_asked:
        # LF_free depends on the speed, heading and hull alone (`low_fidelity.lf_free_stream`): where
        # x_c keeps all three, as it does for a UUV within table 4.2's speeds and headings, it is the
        # `alone` just computed, to the bit (the kernel's free-stream sums never read the field).
        keeps = every_asked and every_near and np.array_equal(clamped[:, 2:], inputs[:, 2:])
        lf_free = alone if keeps else hydro_lf.lf_free_stream(clamped)
        asked_free = free_stream.coefficients(clamped) - lf_free
        if delta is None:
            asked_mean, std = answer()
        else:  # a sample of delta in place of its mean (`interaction_at`); a sample has no std
            asked_mean, std = delta(clamped, np.flatnonzero(asked)), np.nan
    if every_asked:
        mean, free = asked_mean, asked_free
        spread = std if with_std and np.shape(std) == (n, 3) else np.full((n, 3), np.nan)
    else:
        mean, spread, free = np.full((n, 3), np.nan), np.full((n, 3), np.nan), np.full((n, 3), np.nan)
        if any_asked:
            free[asked], mean[asked] = asked_free, asked_mean
            if with_std:
                spread[asked] = std
    correction = np.where(delta_weight[:, None] > 0.0, delta_weight[:, None] * (mean - free), 0.0)
    increment = lf + correction
    rans = np.zeros((n, 3))
    if viscous is not None:
        rans = viscous.blend(inputs, increment, clearance)
        increment = increment + rans
    return increment, reach, mean, spread, lf, free, delta_weight, held, rans
