"""Interaction forces for the sim and the helm: surrogate predictions at the vehicle's state,
turned into dimensional forces with a blend weight (thesis (5.20), SPEC section 5).

The weight is 1 well inside the surrogate's domain (table 4.2 bounds and constraints (4.4)-(4.7))
and falls smoothly to 0 across a band inside its boundary, so the dynamics move from (5.20) to
(5.10) without a force jump (`dynamics.Interaction`). A force model is anything with
`predict(inputs) -> surrogate.Prediction`: the in-process `surrogate.Surrogate`, or
`apps.services.RemoteSurrogate`, which asks the surrogate server over the bus. Both compute the
same numbers.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from nearsub.common.hydro import free_stream as fs
from nearsub.common.physics.dynamics import PSI, Interaction, U, X, Y
from nearsub.common.physics.vehicles import Vehicle
from nearsub.common.surrogate import domain
from nearsub.common.surrogate import model as sg

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


class ServiceError(RuntimeError):
    """A service the mission depends on (the surrogate server) is missing or failed."""


class IncrementError(ServiceError):
    """The "increment" mode has no free-stream table made for the surrogate it is given."""


class ForceModel(Protocol):
    def predict(self, inputs: np.ndarray, return_std: bool = True) -> sg.Prediction: ...


def smoothstep(x: np.ndarray) -> np.ndarray:
    """0 below 0, 1 above 1, x^2 (3 - 2x) between: continuous with a continuous slope."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def blend_weight(inputs: np.ndarray, bounds: np.ndarray = domain.BOUNDS) -> np.ndarray:
    """(n,) weight of the surrogate's forces at inputs (n, 6). The ramp runs inside the bounds of
    the state inputs (position, speed, heading) and the constraints; the hull ratios are constants
    of a vehicle, so they switch the surrogate on or off for a whole mission (see `interaction_at`)."""
    inputs = np.atleast_2d(inputs)
    span = bounds[:, 1] - bounds[:, 0]
    inside = np.minimum(inputs - bounds[:, 0], bounds[:, 1] - inputs) / (BLEND_FRACTION * span)
    inside[:, GEOMETRY] = np.where(inside[:, GEOMETRY] >= 0, np.inf, -np.inf)
    feasible = domain.constraint_values(inputs) / CONSTRAINT_BAND
    margin = np.minimum(inside.min(axis=1), feasible.min(axis=1))
    return smoothstep(np.where(np.isfinite(margin), margin, 0.0))


@dataclass(frozen=True)
class InteractionAt:
    """The surrogate's view of one or more vehicle states."""

    interaction: Interaction  # what the dynamics add (forces and weight)
    forces: np.ndarray  # (n, 3) X_s, Y_s, N_s [N, N, N m], frame convention, unweighted; "increment": the increment
    std: np.ndarray  # (n, 3) their standard deviations
    in_domain: np.ndarray
    constraints_ok: np.ndarray


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
    `weighted_only` the model is asked only about the states whose blend weight is above zero, and
    the others get zero forces: the dynamics multiply them by that zero weight, so the motion is
    the same (to the sign of a zero), and a sweep where most UUVs are outside the domain is cheap.

    In "increment" mode the forces are the prediction minus the free-stream value (`free_stream`,
    or the table made for the model, `increment_table`) at the same clipped inputs, so they tend to
    zero away from the submarine (SPEC section 5); the std is the prediction's."""
    table = None
    if mode == "increment":
        table = free_stream if free_stream is not None else increment_table(model)
    single = np.ndim(state) == 1
    state = np.atleast_2d(state)
    u, x, y, psi = state[:, U], state[:, X], state[:, Y], state[:, PSI]
    raw, mirror = domain.to_inputs(x, y, u, psi, vehicle.length, vehicle.diameter)
    inputs = raw.copy()
    inputs[:, GEOMETRY] = np.clip(raw[:, GEOMETRY], domain.BOUNDS[GEOMETRY, 0], domain.BOUNDS[GEOMETRY, 1])
    weight = blend_weight(inputs)
    asked = weight > 0.0 if weighted_only else np.ones(len(inputs), dtype=bool)
    mean, spread = np.zeros((len(inputs), 3)), np.full((len(inputs), 3), np.nan)
    free = np.zeros((len(inputs), 3))
    if asked.any():
        prediction = model.predict(inputs[asked], return_std=with_std)
        mean[asked] = prediction.mean
        if table is not None:
            free[asked] = table.coefficients(inputs[asked])
        if with_std:
            spread[asked] = prediction.std
    forces = domain.to_forces(mean if table is None else mean - free, mirror, u, vehicle.length, rho)
    std = np.abs(domain.to_forces(spread, mirror, u, vehicle.length, rho))
    safe = np.where(np.isfinite(forces), forces, 0.0)  # weight is 0 wherever they are not finite
    interaction = Interaction(safe[0], weight[0], mode) if single else Interaction(safe, weight, mode)
    return InteractionAt(interaction, forces, std, domain.in_domain(raw), domain.constraints_ok(raw))
