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
HEADING = 3  # psi_deg: the discrepancy weight of the LF-in-the-loop increment ignores it
LATERAL = 1  # constraint (4.5), the outer lateral edge of the trained window
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


def smoothstep(x: np.ndarray) -> np.ndarray:
    """0 below 0, 1 above 1, x^2 (3 - 2x) between: continuous with a continuous slope."""
    x = np.minimum(np.maximum(x, 0.0), 1.0)  # np.clip's bits (x * x drops a zero's sign) at less cost
    return x * x * (3.0 - 2.0 * x)


def _ramps(bounds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lower and upper bounds (6,) and the ramps' widths inside them."""
    lower, upper = np.ascontiguousarray(bounds[:, 0]), np.ascontiguousarray(bounds[:, 1])
    return lower, upper, BLEND_FRACTION * (upper - lower)


_RAMPS = _ramps(domain.BOUNDS)  # table 4.2's, which every step of a mission asks about


Known = tuple[np.ndarray, np.ndarray]  # input rows (n, 6) and their `domain.constraint_values`


def _constraint_values(X: np.ndarray, known: Known | None = None) -> np.ndarray:
    """`domain.constraint_values` of rows X (n, 6), or the values `known` has for the same numbers
    (a row's values depend on its numbers alone): a step asks about its inputs up to three times."""
    if known is not None and X.shape == known[0].shape and np.array_equal(X, known[0]):
        return known[1]
    return domain.constraint_values(X)


def _margins(
    inputs: np.ndarray, bounds: np.ndarray, heading: bool, known: Known | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Ramp coordinates (1 and above: in full, 0 and below: off) of inputs (n, 6): (n, 6) for the
    bounds, (n, 4) for the constraints (4.4)-(4.7)."""
    inputs = np.atleast_2d(inputs)
    lower, upper, ramp = _RAMPS if bounds is domain.BOUNDS else _ramps(bounds)
    inside = np.minimum(inputs - lower, upper - inputs) / ramp
    inside[:, GEOMETRY] = np.where(inside[:, GEOMETRY] >= 0, np.inf, -np.inf)
    if not heading:
        inside[:, HEADING] = np.inf
    return inside, _constraint_values(inputs, known) / CONSTRAINT_BAND


def _weight(inside: np.ndarray, feasible: np.ndarray) -> np.ndarray:
    margin = np.minimum(inside.min(axis=1), feasible.min(axis=1))
    return smoothstep(np.where(np.isfinite(margin), margin, 0.0))


def blend_weight(
    inputs: np.ndarray, bounds: np.ndarray = domain.BOUNDS, heading: bool = True, known: Known | None = None
) -> np.ndarray:
    """(n,) weight of the surrogate's forces at inputs (n, 6). The ramp runs inside the bounds of
    the state inputs (position, speed and, with `heading`, the heading) and the constraints; the
    hull ratios are constants of a vehicle, so they switch the surrogate on or off for a whole
    mission (see `interaction_at`). (4.4)-(4.7) hold no heading term (docs/design.md, "Thesis
    errata": (4.4) has 0.27 sin(2 deg) as a constant), so without `heading` it does not depend on
    psi at all. `known`: constraint values already computed (`_constraint_values`)."""
    return _weight(*_margins(inputs, bounds, heading, known))


def discrepancy_weight(inputs: np.ndarray, known: Known | None = None) -> np.ndarray:
    """(n,) weight w of delta in the LF-in-the-loop increment: `blend_weight` without its heading
    ramp, and across (4.5) the outward ramp of DELTA_TAPER instead of the inward one."""
    inside, feasible = _margins(inputs, domain.BOUNDS, heading=False, known=known)
    # (4.5) is in units of D_sub (8.575 R_lat = y_dist / D_sub), so one D_uuv is 1 / (D_sub/D_uuv).
    taper = DELTA_TAPER / np.atleast_2d(inputs)[:, 4]
    feasible[:, LATERAL] = 1.0 + feasible[:, LATERAL] * CONSTRAINT_BAND[LATERAL] / taper
    return _weight(inside, feasible)


def discrepancy_inputs(inputs: np.ndarray, known: Known | None = None) -> np.ndarray:
    """x_c: inputs (n, 6) clamped into table 4.2's box and then, beyond (4.5), R_lat onto its edge
    (where `discrepancy_weight` tapers delta off), so delta is asked only where it was trained."""
    clamped = np.minimum(np.maximum(inputs, _RAMPS[0]), _RAMPS[1])  # np.clip: no bound is 0
    beyond = np.minimum(_constraint_values(clamped, known)[:, LATERAL], 0.0)
    clamped[:, 1] += beyond / 8.575  # (4.5) falls by 8.575 (= L_sub / D_sub) per unit of R_lat
    return clamped


def prepare(mode: str) -> None:
    """Tabulate the LF's submarine field now (a few seconds, once per process) when `mode` may put
    the LF in the loop, so that an app's first step does not pay for it within the step timeout."""
    if mode == "increment":
        hydro_lf.submarine_field()


def lf_reach_weight(x: np.ndarray, y: np.ndarray, clearance: np.ndarray | None = None) -> np.ndarray:
    """(n,) weight of the LF increment at CB positions x, y [m] (submarine frame): 1 up to LF_FULL
    of clearance from the hull, 0 beyond LF_CUT, smooth between. Independent of the heading.
    `clearance`: `proximity.hull_signed_distance(x, y)`, if already known."""
    if clearance is None:
        clearance = proximity.hull_signed_distance(x, y)
    weight = 1.0 - smoothstep((clearance - LF_FULL) / (LF_CUT - LF_FULL))
    return np.where(np.isfinite(weight), weight, 0.0)  # a non-finite state: no interaction


FLAG_NAMES = domain.INPUT_NAMES + domain.CONSTRAINT_NAMES  # columns of InteractionAt.outside_mask


@dataclass(frozen=True)
class InteractionAt:
    """The surrogate's view of one or more vehicle states, (n, ...) arrays.

    `interaction` is what the dynamics use: forces and weight (shaped as the state). `forces` are
    those forces before the weight, `applied` = weight x forces, the surrogate's share of the
    (5.11)/(5.20) right-hand side (in "increment" mode exactly what is added to (5.11); in
    "replace"/"thesis" the (5.10) terms it stands for enter with 1 - weight). `model` and `std` are
    the model's raw answer and its std: the discrepancy delta(x_c) in the LF-in-the-loop
    increment, the prediction otherwise; `lf` the LF increment LF(x) - LF_free(x) (NaN when the
    mode does not use it); `delta_free` the free-stream part of delta, HF_free(x_c) - LF_free(x_c),
    which the increment leaves out (NaN likewise); `delta_weight` the weight of delta (NaN
    likewise), `viscous` the viscous correction's change (zero without one), so forces = lf +
    delta_weight (model - delta_free) + viscous. All in N and N m,
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


def outside_mask(raw: np.ndarray, known: Known | None = None) -> np.ndarray:
    """(n, 10) True where a raw input lies outside table 4.2's bounds (non-finite included) or a
    constraint (4.4)-(4.7) fails, columns FLAG_NAMES. `known`: as in `blend_weight`."""
    with np.errstate(invalid="ignore"):
        beyond = ~((raw >= domain.BOUNDS[:, 0]) & (raw <= domain.BOUNDS[:, 1]))
        return np.hstack([beyond, ~(_constraint_values(raw, known) >= 0.0)])


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
    `with_std` the std is NaN (sweeps do not need it; the mean is the same either way). With
    `weighted_only` the model is asked only about the states whose weight is above zero, and the
    others get zero forces: the dynamics multiply them by that zero weight, so the motion is the
    same (to the sign of a zero), and a sweep where most UUVs are outside the domain is cheap.

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
    inputs = raw.copy()
    inputs[:, GEOMETRY] = np.minimum(np.maximum(raw[:, GEOMETRY], _GEOMETRY_LOWER), _GEOMETRY_UPPER)
    n = len(inputs)
    known = (inputs, domain.constraint_values(inputs))  # for the weights, x_c and the flags
    table = None
    if mode == "increment":
        table = free_stream if free_stream is not None else increment_table(model)
    if mode == "increment" and getattr(model, "kind", None) == "lf_in_loop":
        correction = viscous_correction(model) if viscous else None
        coefficients, weight, model_mean, spread, lf, delta_free, delta_weight, held, rans = lf_in_loop_increment(
            model, inputs, x, y, vehicle, table, with_std, weighted_only, delta, known, correction
        )
    elif delta is not None:
        raise ValueError(f'a sampled delta needs the "increment" mode and a model of kind "lf_in_loop", got {mode!r}')
    else:
        weight = blend_weight(inputs, known=known)
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
        delta_weight, held = np.full(n, np.nan), np.zeros(n, dtype=bool)
        rans = np.zeros((n, 3))
    # One conversion for the six (n, 3) arrays (element-wise, so each gets its own bits).
    parts = np.concatenate([coefficients, model_mean, spread, lf, delta_free, rans])
    converted = domain.to_forces(parts, np.concatenate((mirror,) * 6), np.concatenate((u,) * 6), vehicle.length, rho)
    forces, model_forces, spread_forces, lf_forces, free_forces, rans_forces = converted.reshape(6, n, 3)
    safe = np.where(np.isfinite(forces), forces, 0.0)  # weight is 0 wherever they are not finite
    interaction = Interaction(safe[0], weight[0], mode) if single else Interaction(safe, weight, mode)
    flags = outside_mask(raw, known)
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
    weighted_only: bool = False,
    delta: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    known: Known | None = None,
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
    from the submarine. Without `weighted_only` delta is asked about every state (the sim
    publishes it); with it only where both weights are above zero (a sweep). `delta`: as in
    `interaction_at`; `known`: as in `blend_weight`."""
    if vehicle.length > LF_MAX_LENGTH:
        raise ValueError(
            f"vehicle {vehicle.name}: {vehicle.length:g} m long, longer than the {LF_MAX_LENGTH:.2f} m the LF's "
            f"field table serves at the increment's cut-off ({LF_CUT:g} m from the hull)"
        )
    n = len(inputs)
    clearance = proximity.hull_signed_distance(x, y)  # the LF's reach and the viscous correction's input
    reach = lf_reach_weight(x, y, clearance)
    delta_weight = discrepancy_weight(inputs, known)
    near = reach > 0.0
    asked = near & (delta_weight > 0.0) if weighted_only else np.ones(n, dtype=bool)
    # Every row (the sim's one vehicle, a batch near the hull) needs no masked copies.
    every_asked, every_near = n > 0 and bool(asked.all()), n > 0 and bool(near.all())
    if any_asked := every_asked or asked.any():
        clamped = discrepancy_inputs(inputs if every_asked else inputs[asked], known)
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
        mean, spread, free = np.zeros((n, 3)), np.full((n, 3), np.nan), np.zeros((n, 3))
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
