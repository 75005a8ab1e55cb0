"""Interaction forces for the sim and the helm: surrogate predictions at the vehicle's state,
turned into dimensional forces with a blend weight (thesis (5.20); docs/design.md, "Physics
decisions").

Replace and thesis modes, and the increment mode of a model without the LF in the loop: the
weight is 1 well inside the surrogate's domain (table 4.2 bounds and constraints (4.4)-(4.7)) and
falls smoothly to 0 across a band inside its boundary, heading included, so the dynamics move from
(5.20) to (5.10) without a force jump (`dynamics.Interaction`).

Increment mode with the LF in the loop (a model of kind "lf_in_loop", the default): the increment
added to (5.11) is [LF(x) - LF_free(x)] + w(x) delta(x_c) (`lf_in_loop_increment`). The exact low
fidelity (`hydro.low_fidelity`) carries the heading and distance dependence at the true pose x, at
any heading; the residual GP delta corrects it at x_c, x clamped into table 4.2's box, with a
weight w of position, speed and the constraints that never depends on the heading. The LF runs
here, in the process that needs the force (the sim, the helm, the batch engine): it costs well
under a millisecond, and computing it where it is used keeps one code path for in-process,
multi-process and batch runs, so they agree bit for bit; the surrogate server answers only
delta (`discrepancy`).

A force model is anything with `predict(inputs) -> surrogate.Prediction` (and, for the LF in the
loop, `kind` and `discrepancy`): the in-process `surrogate.Surrogate`, or
`apps.services.RemoteSurrogate`, which asks the surrogate server over the bus. Both compute the
same numbers.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from nearsub.common.hydro import free_stream as fs
from nearsub.common.hydro import low_fidelity as hydro_lf
from nearsub.common.physics import proximity
from nearsub.common.physics.dynamics import PSI, Interaction, U, X, Y
from nearsub.common.physics.hull import R_SUB
from nearsub.common.physics.vehicles import Vehicle
from nearsub.common.surrogate import domain
from nearsub.common.surrogate import query as sg
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
HEADING = 3  # psi_deg: the discrepancy weight of the LF-in-the-loop increment ignores it
# Reach of the LF increment, in clearance of the UUV's CB from the submarine's outline
# (`proximity.hull_signed_distance`): in full up to LF_FULL, then cut off smoothly (smoothstep) to
# zero at LF_CUT. nearsub's choice, set by the LF's tabulated field, which ends 25 m from the
# submarine's axis (`low_fidelity.R_FIELD_MAX`): LF_CUT plus R_sub plus a UUV's length
# (`LF_MAX_LENGTH`, 5.8 m, above every library vehicle) stays inside it. Measured with
# `lf_increment_terms` at psi = 0, R_long -0.65 to 0.65: at 14 m the increment is still up to 7 %
# (REMUS 100) and 17 % (SDV) of the vehicle's own free-stream drag in X', and about 60 % of its
# own Munk moment at 2 deg in N' (it decays about as 1 / clearance there). So this cut-off is
# where the table ends, not where the increment has become a small fraction of the vehicle's own
# forces; a wider field table (a new LF version) would move it out.
LF_FULL = 9.0  # [m]
LF_CUT = 14.0  # [m]
LF_MAX_LENGTH = hydro_lf.R_FIELD_MAX - R_SUB - LF_CUT  # longest UUV whose strips stay in the table [m]


class IncrementError(ServiceError):
    """The "increment" mode has no free-stream table made for the surrogate it is given."""


class ForceModel(Protocol):
    kind: str  # "lf_in_loop", "multi_fidelity" or "gp"

    def predict(self, inputs: np.ndarray, return_std: bool = True) -> sg.Prediction: ...

    def discrepancy(self, inputs: np.ndarray, return_std: bool = True) -> tuple[np.ndarray, np.ndarray | None]: ...


def smoothstep(x: np.ndarray) -> np.ndarray:
    """0 below 0, 1 above 1, x^2 (3 - 2x) between: continuous with a continuous slope."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def blend_weight(inputs: np.ndarray, bounds: np.ndarray = domain.BOUNDS, heading: bool = True) -> np.ndarray:
    """(n,) weight of the surrogate's forces at inputs (n, 6). The ramp runs inside the bounds of
    the state inputs (position, speed and, with `heading`, the heading) and the constraints; the
    hull ratios are constants of a vehicle, so they switch the surrogate on or off for a whole
    mission (see `interaction_at`). Without `heading` the weight is that of the discrepancy in the
    LF-in-the-loop increment: (4.4)-(4.7) hold no heading term either (docs/design.md, "Thesis
    errata": (4.4) has 0.27 sin(2 deg) as a constant), so it does not depend on psi at all."""
    inputs = np.atleast_2d(inputs)
    span = bounds[:, 1] - bounds[:, 0]
    inside = np.minimum(inputs - bounds[:, 0], bounds[:, 1] - inputs) / (BLEND_FRACTION * span)
    inside[:, GEOMETRY] = np.where(inside[:, GEOMETRY] >= 0, np.inf, -np.inf)
    if not heading:
        inside[:, HEADING] = np.inf
    feasible = domain.constraint_values(inputs) / CONSTRAINT_BAND
    margin = np.minimum(inside.min(axis=1), feasible.min(axis=1))
    return smoothstep(np.where(np.isfinite(margin), margin, 0.0))


def prepare(mode: str) -> None:
    """Tabulate the LF's submarine field now (a few seconds, once per process) when `mode` may put
    the LF in the loop, so that an app's first step does not pay for it within the step timeout."""
    if mode == "increment":
        hydro_lf.submarine_field()


def lf_reach_weight(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(n,) weight of the LF increment at CB positions x, y [m] (submarine frame): 1 up to LF_FULL
    of clearance from the hull, 0 beyond LF_CUT, smooth between. Independent of the heading."""
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
    mode does not use it); `delta_weight` the weight of delta (NaN likewise). All in N and N m,
    frame convention. `outside_mask` (n, 10) says which inputs (table 4.2) and constraints
    (4.4)-(4.7) the state is outside of (`outside`), `lf_held` where the LF held its field at the
    table's inner edge (the UUV within 1 cm of the submarine's widest radius, `low_fidelity`)."""

    interaction: Interaction
    forces: np.ndarray
    applied: np.ndarray
    model: np.ndarray
    std: np.ndarray
    lf: np.ndarray
    delta_weight: np.ndarray
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
    with np.errstate(invalid="ignore"):
        beyond = ~((raw >= domain.BOUNDS[:, 0]) & (raw <= domain.BOUNDS[:, 1]))
        return np.hstack([beyond, ~(domain.constraint_values(raw) >= 0.0)])


HULL_SHAPE_CONSTRAINTS = [2, 3]  # (4.6) and (4.7): functions of the hull ratios alone


def geometry_outside(vehicle: Vehicle) -> str | None:
    """Why the vehicle's hull is outside the surrogate's trained hulls (table 4.2, or the hull-shape
    constraints (4.6)/(4.7), which switch the interaction off everywhere), or None."""
    inputs, _ = domain.to_inputs(0.0, 0.0, 0.0, 0.0, vehicle.length, vehicle.diameter)
    lower, upper = domain.BOUNDS[GEOMETRY, 0], domain.BOUNDS[GEOMETRY, 1]
    inputs[:, GEOMETRY] = np.clip(inputs[:, GEOMETRY], lower, upper)  # as interaction_at evaluates it
    shape = domain.constraint_values(inputs)[0, HULL_SHAPE_CONSTRAINTS]
    if np.any(shape < 0):
        names = [domain.CONSTRAINT_NAMES[i] for i in HULL_SHAPE_CONSTRAINTS]
        failed = ", ".join(f"{n} = {v:.3g} < 0" for n, v in zip(names, shape, strict=True) if v < 0)
        return (
            f"vehicle {vehicle.name}: hull outside the surrogate's constraints ({failed}); the interaction "
            "forces are zero everywhere for this vehicle"
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


def _served_model_id(model: ForceModel) -> str | None:
    """The content hash of the model behind `model`: `Surrogate.model_id`, or, for the surrogate
    server (apps.services.RemoteSurrogate, which does not keep it), the model_id of one reply."""
    if getattr(model, "model_id", None) is not None or not hasattr(model, "_querier"):
        return getattr(model, "model_id", None)
    try:
        payload = model._querier.ask(sg.encode_query(domain.BOUNDS.mean(axis=1)))
        return sg.decode_reply(payload).model_id
    except (RuntimeError, ValueError) as exc:  # bus.ReplyError, messages.MessageError (no Zenoh import here)
        raise ServiceError(f"surrogate server: {exc}") from None


def increment_table(model: ForceModel) -> fs.FreeStreamTable:
    """The free-stream table made for this model (cached per model object); raises IncrementError,
    naming the mission field and the model file, when there is none: adding the surrogate's total
    forces (which hold the UUV's own drag and Munk moment) on top of (5.11) would count them twice."""
    try:
        return _TABLES[model]
    except (KeyError, TypeError):
        pass
    model_id = _served_model_id(model)
    loaded = getattr(model, "loaded", None)
    path = getattr(loaded, "path", None)
    try:
        table, searched = fs.find_table(model_id, path)
    except fs.FreeStreamFileError as exc:
        raise IncrementError(f'apps.sim.interaction = "increment": {exc}') from None
    if table is None:
        source = getattr(model, "source", None) or path or "the surrogate server's model (surrogate.model)"
        raise IncrementError(
            f'apps.sim.interaction = "increment" needs the free-stream value of the hydrodynamic model that '
            f"the surrogate {source} (model id {model_id}) was trained on, and no free-stream table matches "
            f"that model (looked at {', '.join(str(p) for p in searched)}). Use the shipped model "
            "(surrogate.model empty), build the table of a model trained on common/hydro_hf.py with "
            '"python -m nearsub.tools.free_stream MODEL", or set apps.sim.interaction = "replace".'
        )
    try:
        _TABLES[model] = table
    except TypeError:  # a model object without weak references: look it up every call
        pass
    return table


def interaction_at(
    model: ForceModel,
    state: np.ndarray,
    vehicle: Vehicle,
    rho: float,
    mode: str,
    with_std: bool = True,
    weighted_only: bool = False,
    free_stream: fs.FreeStreamTable | None = None,
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

    "increment" with a model of kind "lf_in_loop": `lf_in_loop_increment`. "increment" with another
    model: the prediction minus the free-stream value (`free_stream`, or the table made for the
    model, `increment_table`) at the same clipped inputs, with the blend weight; "replace" and
    "thesis": the prediction with the blend weight."""
    single = np.ndim(state) == 1
    state = np.atleast_2d(state)
    u, x, y, psi = state[:, U], state[:, X], state[:, Y], state[:, PSI]
    raw, mirror = domain.to_inputs(x, y, u, psi, vehicle.length, vehicle.diameter)
    inputs = raw.copy()
    inputs[:, GEOMETRY] = np.clip(raw[:, GEOMETRY], domain.BOUNDS[GEOMETRY, 0], domain.BOUNDS[GEOMETRY, 1])
    n = len(inputs)
    if mode == "increment" and getattr(model, "kind", None) == "lf_in_loop":
        coefficients, weight, model_mean, spread, lf, delta_weight, held = lf_in_loop_increment(
            model, inputs, x, y, vehicle, with_std, weighted_only
        )
    else:
        table = None
        if mode == "increment":
            table = free_stream if free_stream is not None else increment_table(model)
        weight = blend_weight(inputs)
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
        lf, delta_weight, held = np.full((n, 3), np.nan), np.full(n, np.nan), np.zeros(n, dtype=bool)
    # One conversion for the four (n, 3) arrays (element-wise, so each gets its own bits).
    parts = np.vstack([coefficients, model_mean, spread, lf])
    forces, model_forces, spread_forces, lf_forces = np.split(
        domain.to_forces(parts, np.tile(mirror, 4), np.tile(u, 4), vehicle.length, rho), 4
    )
    safe = np.where(np.isfinite(forces), forces, 0.0)  # weight is 0 wherever they are not finite
    interaction = Interaction(safe[0], weight[0], mode) if single else Interaction(safe, weight, mode)
    flags = outside_mask(raw)
    return InteractionAt(
        interaction=interaction,
        forces=forces,
        applied=weight[:, None] * safe,
        model=model_forces,
        std=np.abs(spread_forces),
        lf=lf_forces,
        delta_weight=delta_weight,
        in_domain=~flags[:, : len(domain.INPUT_NAMES)].any(axis=1),
        constraints_ok=~flags[:, len(domain.INPUT_NAMES) :].any(axis=1),
        outside_mask=flags,
        lf_held=held,
    )


def lf_in_loop_increment(
    model: ForceModel,
    inputs: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    vehicle: Vehicle,
    with_std: bool = True,
    weighted_only: bool = False,
):
    """The increment [LF(x) - LF_free(x)] + w(x) delta(x_c) in coefficients (n, 3) at inputs (n, 6)
    (hull ratios clipped) of UUVs at CB positions x, y, with the dynamics' weight (the LF's reach,
    `lf_reach_weight`), and the parts: delta's mean and std (n, 3) at x_c, the LF increment (n, 3),
    w (n,) and where the LF held its field (n,) (`low_fidelity.lf_increment_terms`).

    x_c is x clamped into table 4.2's box; w = `blend_weight` without its heading ramp, so the
    LF alone carries the heading dependence beyond +/-2 deg, continuously. LF_free is the same
    model's lone UUV at the same hull, speed and heading, so the increment tends to zero away
    from the submarine. Without `weighted_only` delta is asked about every state (the sim
    publishes it); with it only where both weights are above zero (a sweep)."""
    if vehicle.length > LF_MAX_LENGTH:
        raise ValueError(
            f"vehicle {vehicle.name}: {vehicle.length:g} m long, longer than the {LF_MAX_LENGTH:.2f} m the LF's "
            f"field table serves at the increment's cut-off ({LF_CUT:g} m from the hull)"
        )
    n = len(inputs)
    reach = lf_reach_weight(x, y)
    delta_weight = blend_weight(inputs, heading=False)
    lf = np.zeros((n, 3))
    held = np.zeros(n, dtype=bool)
    near = reach > 0.0
    if near.any():
        with_sub, alone, held[near] = hydro_lf.lf_increment_terms(inputs[near])
        lf[near] = with_sub - alone
    asked = near & (delta_weight > 0.0) if weighted_only else np.ones(n, dtype=bool)
    mean, spread = np.zeros((n, 3)), np.full((n, 3), np.nan)
    if asked.any():
        clamped = np.clip(inputs[asked], domain.BOUNDS[:, 0], domain.BOUNDS[:, 1])
        mean[asked], std = model.discrepancy(clamped, return_std=with_std)
        if with_std:
            spread[asked] = std
    correction = np.where(delta_weight[:, None] > 0.0, delta_weight[:, None] * mean, 0.0)
    return lf + correction, reach, mean, spread, lf, delta_weight, held
