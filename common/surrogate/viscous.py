"""The viscous correction: RANS as the fidelity above the panel HF, where the product differs from it.

At the RANS two-body stations kept for training (docs/hydro/rans/README.md), RANS's interaction
(a station's forces less those of the same UUV alone) is learned by one GP per output over the
UUV's position along the hull, the log of its centre's clearance from the hull in UUV diameters,
and its heading. Where the stations determine that GP, it takes over from the interaction the
product flies (the LF-in-the-loop increment, `interaction.lf_in_loop_increment`); away from them
the increment is left alone. The share it takes is its own information at the point,
1 - posterior variance / prior variance, per output: near 1 between stations, 0 far from them.
The clearance, not R_lat, is the lateral input because the hull tapers: at the stern the same gap
is a smaller R_lat, and RANS's interaction follows the gap (docs/hydro/rans/two-body-compare.md).
It is the top level of the thesis's multi-fidelity structure (section 2.5) with the lower levels
as its prior where it has no data; the GPs have a zero prior mean (outputs not normalised).

A correction belongs to the model whose increment it corrects (`surrogate_model_id`): it is used only with
that model (`find`), and a retrained model needs a new fit (`nearsub cfd correct`). It is in
coefficients, nondimensionalised by the UUV's own length, and learned mostly on the SDV's hull:
docs/hydro/rans/README.md says what that assumes for other UUVs.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nearsub.common.learning.gp import MultiOutputGP
from nearsub.common.physics.hull import D_SUB, L_SUB
from nearsub.common.physics.proximity import hull_signed_distance
from nearsub.common.surrogate import model as sg
from nearsub.common.surrogate.calibration import loo_predictions

FORMAT_NAME = "nearsub-viscous-correction"
FORMAT_VERSION = 1
# The GPs' inputs (`features`) and the box their length scales refer to: R_long over the hull,
# log(CB clearance / D_uuv) from a centre just off the hull to 30 diameters, the heading in deg.
# The length scales may not go below LENGTH_SCALE_FLOOR of each side: 0.06 L_sub along the hull,
# a quarter of the clearance's log (a gap 28 % larger), half a degree. nearsub's choice: without a
# floor, maximum likelihood on a dozen stations picks spikes at the stations and nothing between.
BOUNDS = np.array([[-0.6, 0.6], [-1.5, 3.5], [-5.0, 5.0]])
LENGTH_SCALE_FLOOR = 0.05
CLEARANCE_FLOOR = 0.25  # [D_uuv]: a centre this close to the hull is outside every station
SCALE = 1e3  # coefficients are fitted x 1e3, so the GPs' variance bounds suit them
# Reach: in full up to the farthest station's lateral distance (R_lat 0.085, beyond (4.5)), zero
# by 0.11 (smoothstep), where neither RANS nor the panel HF find more than 2e-5 of interaction in
# Y' and N' beside the midbody (docs/hydro/rans/two-body-compare.md); along the hull in full over
# it (the stations reach the stern tip, R_long -0.5) and zero 0.15 L_sub beyond either end, so
# that nothing is extrapolated far into the wake or ahead of the bow. nearsub's choice.
R_LAT_FULL = 0.085
R_LAT_CUT = 0.11
R_LONG_FULL = 0.5
R_LONG_CUT = 0.65


class CorrectionFileError(ValueError):
    """A viscous correction file that cannot be read."""


def _fade(value: np.ndarray, full: float, cut: float) -> np.ndarray:
    t = np.minimum(np.maximum((value - full) / (cut - full), 0.0), 1.0)
    return 1.0 - t * t * (3.0 - 2.0 * t)


def reach(inputs: np.ndarray) -> np.ndarray:
    """(n,) weight of the correction at configuration rows (n, 6): 1 within R_LAT_FULL and
    R_LONG_FULL, 0 beyond R_LAT_CUT or R_LONG_CUT, smooth between."""
    inputs = np.atleast_2d(inputs)
    return _fade(inputs[:, 1], R_LAT_FULL, R_LAT_CUT) * _fade(np.abs(inputs[:, 0]), R_LONG_FULL, R_LONG_CUT)


def features(inputs: np.ndarray, clearance: np.ndarray | None = None) -> np.ndarray:
    """The GPs' inputs (n, 3) at configuration rows (n, 6): R_long, log(clearance of the UUV's
    centre from the hull / D_uuv) and psi_deg. `clearance` [m]: that clearance, if known (the
    interaction computes it for the LF's reach); else from the rows."""
    inputs = np.atleast_2d(inputs)
    if clearance is None:
        clearance = hull_signed_distance(inputs[:, 0] * L_SUB, inputs[:, 1] * L_SUB)
    relative = clearance * (inputs[:, 4] / D_SUB)  # in UUV diameters
    return np.column_stack([inputs[:, 0], np.log(np.maximum(relative, CLEARANCE_FLOOR)), inputs[:, 3]])


@dataclass(frozen=True)
class ViscousCorrection:
    """One GP per output and how each is used (`meta["forms"]`): "takeover" (a GP of RANS's
    interaction that takes the increment's place by its share of information), "residual" (a GP
    of RANS's interaction less the increment, added to it) or "none" (the increment as it is)."""

    gp: MultiOutputGP
    meta: dict[str, Any]
    # What every call needs, worked out once: each output's prior variance and form.
    _prior: np.ndarray = field(init=False, repr=False)
    _takeover: np.ndarray = field(init=False, repr=False)
    _residual: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        forms = self.meta["forms"]
        object.__setattr__(self, "_prior", np.array([gp.signal_variance for gp in self.gp.gps]))
        object.__setattr__(self, "_takeover", np.array([form == "takeover" for form in forms]))
        object.__setattr__(self, "_residual", np.array([form == "residual" for form in forms]))

    @property
    def surrogate_model_id(self) -> str | None:
        """The model whose increment this corrects."""
        return self.meta.get("surrogate_model_id")

    def blend(self, inputs: np.ndarray, increment: np.ndarray, clearance: np.ndarray | None = None) -> np.ndarray:
        """The change (n, 3) that takes the product's `increment` (n, 3) at configuration rows
        (n, 6), mirrored as the surrogate's inputs are, towards RANS, times `reach` (zero
        beyond it, where the GPs are not asked). Each row's value has the same bits whatever the
        batch (`MultiOutputGP.predict_rows`). `clearance`: as in `features`."""
        inputs = np.atleast_2d(inputs)
        weight = reach(inputs)
        active = weight > 0.0  # the GPs are asked only where the correction reaches
        if not active.any():
            return np.zeros((len(inputs), 3))
        every = bool(active.all())
        if not every:
            inputs, increment, weight = inputs[active], np.atleast_2d(increment)[active], weight[active]
            clearance = None if clearance is None else np.ravel(clearance)[active]
        mean, std = self.gp.predict_rows(features(inputs, clearance), return_std=True)
        takeover, residual = self._takeover, self._residual
        share = np.where(takeover, np.maximum(1.0 - std * std / self._prior, 0.0), 1.0)
        change = np.where(takeover, share * (mean / SCALE - increment), np.where(residual, mean / SCALE, 0.0))
        if every:
            return weight[:, None] * change
        out = np.zeros((len(active), 3))
        out[active] = weight[:, None] * change
        return out


# "none": RANS does not improve on the increment there. In order of preference on a tie.
FORMS = ("none", "residual", "takeover")


def fit(
    rows: np.ndarray, interaction: np.ndarray, increment: np.ndarray, meta: dict[str, Any], n_restarts: int = 20
) -> ViscousCorrection:
    """Fit the correction to RANS's `interaction` (n, 3) at configuration rows (n, 6), where the
    product flies `increment` (n, 3). Per output the form whose leave-one-out error against RANS
    over the stations is smallest is kept (`meta["loo_mae"]` has each; "none" is the increment's
    own error there). `meta` names the model (`surrogate_model_id`) and the stations."""
    rows, interaction, increment = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (rows, interaction, increment))
    X = features(rows)
    options = dict(bounds=BOUNDS, normalize=False, length_scale_bounds=(LENGTH_SCALE_FLOOR, 1.0))
    fitted = {
        form: MultiOutputGP(n_restarts=n_restarts, seed=0, **options).fit(
            X, (interaction if form == "takeover" else interaction - increment) * SCALE
        )
        for form in ("residual", "takeover")
    }
    fitted["none"] = fitted["residual"]  # kept in the file, never used
    weight = reach(rows)
    errors = {"none": np.mean(np.abs(increment - interaction), axis=0).tolist()}
    for form in ("residual", "takeover"):
        model = fitted[form]
        columns = []
        for j, gp in enumerate(model.gps):
            mean, variance = loo_predictions(gp)  # normalize=False: in the fitted units
            mean = mean / SCALE
            if form == "takeover":
                share = np.maximum(1.0 - variance / gp.signal_variance, 0.0)
                value = increment[:, j] + weight * share * (mean - increment[:, j])
            else:
                value = increment[:, j] + weight * mean
            columns.append(float(np.mean(np.abs(value - interaction[:, j]))))
        errors[form] = columns
    forms = [min(FORMS, key=lambda f: errors[f][j]) for j in range(interaction.shape[1])]
    states = {form: model.get_state() for form, model in fitted.items()}
    chosen = MultiOutputGP.from_state(
        {
            "X": X,
            "Y": np.column_stack([states[form]["Y"][:, j] for j, form in enumerate(forms)]),
            "seed": 0,
            "outputs": [states[form]["outputs"][j] for j, form in enumerate(forms)],
        }
    )
    meta = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "forms": forms, "loo_mae": errors, **meta}
    return ViscousCorrection(chosen, meta)


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def save(path: str | os.PathLike, correction: ViscousCorrection) -> Path:
    """Write the correction as JSON (floats as Python writes them: they read back to the bit)."""
    path = Path(path)
    text = json.dumps({"meta": correction.meta, "gp": _plain(correction.gp.get_state())}, indent=1, sort_keys=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text + "\n")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def load(path: str | os.PathLike) -> ViscousCorrection:
    try:
        data = json.loads(Path(path).read_text())
        meta = data["meta"]
        model = MultiOutputGP.from_state(data["gp"])
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise CorrectionFileError(f"{path}: not a readable viscous correction ({exc})") from None
    if meta.get("format") != FORMAT_NAME or meta.get("version") != FORMAT_VERSION:
        raise CorrectionFileError(
            f"{path}: format {meta.get('format')!r} version {meta.get('version')!r}, "
            f"expected {FORMAT_NAME!r} version {FORMAT_VERSION}"
        )
    return ViscousCorrection(model, meta)


SUFFIX = "-viscous.json"


def default_path() -> Path:
    """The shipped correction, of the shipped surrogate (package data `data/*`)."""
    return sg.companion_path(sg.default_model_path(), SUFFIX)


def path_for(model_path: str | os.PathLike) -> Path:
    """Where the correction of a model file lives: next to it, `<stem>-viscous.json`."""
    return sg.companion_path(model_path, SUFFIX)


def find(model_id: str | None, model_path: str | os.PathLike | None) -> ViscousCorrection | None:
    """The correction made for the surrogate `model_id` (`model.find_companion`), or None."""
    return sg.find_companion(model_id, model_path, SUFFIX, load)[0]
