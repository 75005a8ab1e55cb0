"""Two-body RANS stations side by side with the product's other fidelities: the panel HF, the LF,
the shipped surrogate's prediction and what the product flies (`nearsub cfd compare`;
docs/hydro/rans/README.md, "Two-body stations")."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from nearsub.common.hydro import rans
from nearsub.common.hydro.rans_campaign import station_of

OUTPUTS = ("X", "Y", "N")
# The other fidelities at a station, against RANS: the panel HF (high_fidelity, MEDIUM panels),
# the LF, the shipped surrogate's prediction (LF + delta at the point, as `nearsub surrogate`
# answers), and what the product flies (LF + w delta(x_c): interaction.discrepancy_weight, 0 beyond
# (4.5) and outside table 4.2's box; the LF's field held at its inner edge inside the widest radius).
FIDELITIES = ("panel HF", "LF", "model", "flown")
# The panel HF times one factor per output fitted on the training stations: how much of its
# difference from RANS one scale explains (`fitted_scale`).
SCALED = "panel HF x rho"


def standard_setup(r: rans.Result) -> bool:
    """Solved as the two-body and UUV-alone suites are (SST, the default wall function, y+ and
    inflow): the comparison, the interaction alone and the viscous correction take only these, so a
    study's variant of a station (k-omega, another inflow: its own case id) never stands in for it
    or for its UUV alone."""
    return (
        r.turbulence == "sst"
        and r.wall_function == "nutk"
        and r.y_plus_target == 50.0
        and r.inflow_intensity == rans.INFLOW_INTENSITY
        and r.inflow_viscosity_ratio == rans.INFLOW_VISCOSITY_RATIO
    )


def two_body_converged(found: Iterable[rans.Result]) -> list[rans.Result]:
    """The converged two-body results of the standard setup (the only ones compared), by R_long
    then the case id."""
    kept = [
        r for r in found if r.kind == "two-body" and r.convergence.usable and r.inputs is not None and standard_setup(r)
    ]
    return sorted(kept, key=lambda r: (r.inputs[0], r.case_id))


def fidelity_values(rows: np.ndarray) -> dict[str, np.ndarray]:
    """[X', Y', N'] (n, 3) of each of FIDELITIES at configuration rows (n, 6)."""
    from nearsub.common.hydro.high_fidelity import MEDIUM, hf_coefficients
    from nearsub.common.hydro.low_fidelity import lf_coefficients, lf_increment_terms
    from nearsub.common.surrogate import interaction
    from nearsub.common.surrogate.model import load_surrogate

    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    lf = np.asarray(lf_coefficients(rows), dtype=float)
    surrogate = load_surrogate()
    model = np.asarray(surrogate.predict(rows, return_std=False).mean, dtype=float)
    delta, _ = surrogate.discrepancy(interaction.discrepancy_inputs(rows.copy()), return_std=False)
    # The loop holds the LF's field at its inner edge where the UUV reaches inside the submarine's
    # widest radius (the tapering stern), where `lf_coefficients` is NaN: the flown value is that.
    held_lf = np.asarray(lf_increment_terms(rows)[0], dtype=float)
    flown = held_lf + interaction.discrepancy_weight(rows)[:, None] * np.asarray(delta, dtype=float)
    hf = np.asarray(hf_coefficients(rows, panels=MEDIUM), dtype=float)
    return {"panel HF": hf, "LF": lf, "model": model, "flown": flown}


def comparison_rows(
    results: list[rans.Result], values: dict[str, np.ndarray], truth: np.ndarray | None = None
) -> list[dict]:
    """One row per RANS result: its station, X', Y', N' (or the rows of `truth` (n, 3): its
    interaction alone), and for each fidelity in `values` (arrays (n, 3) in the order of `results`)
    its X', Y', N', the difference from RANS (other - RANS) and that difference relative to |RANS|."""
    out = []
    for i, r in enumerate(results):
        station = station_of(r.inputs)
        rans_values = np.array([r.coefficients[k] for k in OUTPUTS]) if truth is None else np.asarray(truth[i])
        row = {
            "case": r.case_id,
            "station": station.name if station else "",
            "held_out": bool(station and station.held_out),
            "inputs": list(r.inputs),
            "level": r.level,
            "cells": r.cells,
            "minutes": r.wall_seconds / 60,
            "RANS": rans_values.tolist(),
        }
        for name, table in values.items():
            other = np.asarray(table, dtype=float)[i]
            difference = other - rans_values
            row[name] = other.tolist()
            row[f"{name} - RANS"] = difference.tolist()
            with np.errstate(divide="ignore", invalid="ignore"):
                row[f"{name} rel"] = (difference / np.abs(rans_values)).tolist()
        out.append(row)
    return out


def comparison_summary(rows: list[dict], fidelities: Iterable[str] = FIDELITIES) -> dict[str, dict[str, list[float]]]:
    """Per fidelity: the mean absolute difference from RANS of X', Y', N' over all rows and over
    the held-out stations (their medium mesh only, one row a station: the grid study's other
    meshes of a held-out station are not more stations; NaN where there are none), and how often
    the sign of each output agrees."""
    out = {}
    for name in fidelities:
        if not rows or name not in rows[0]:
            continue
        diff = np.array([r[f"{name} - RANS"] for r in rows], dtype=float)
        held = np.array([r["held_out"] and r["level"] == "medium" for r in rows], dtype=bool)
        signs = np.sign(np.array([r[name] for r in rows])) == np.sign(np.array([r["RANS"] for r in rows]))
        out[name] = {
            "mae": np.nanmean(np.abs(diff), axis=0).tolist(),
            "mae_held_out": (np.nanmean(np.abs(diff[held]), axis=0) if held.any() else np.full(3, np.nan)).tolist(),
            "sign_agrees": signs.mean(axis=0).tolist(),
        }
    return out


def fitted_scale(rows: list[dict]) -> np.ndarray:
    """Per output, the rho for which rho * (panel HF) is closest to RANS in least squares over the
    medium-mesh stations kept for training (not held out): the autoregressive link between two
    fidelities of Kennedy & O'Hagan (2000) with a constant scale and no discrepancy of its own.
    NaN where there is no training station."""
    train = [r for r in rows if not r["held_out"] and r["level"] == "medium"]
    if not train:
        return np.full(len(OUTPUTS), np.nan)
    hf = np.array([r["panel HF"] for r in train], dtype=float)
    truth = np.array([r["RANS"] for r in train], dtype=float)
    return (hf * truth).sum(axis=0) / (hf * hf).sum(axis=0)


# --- the interaction alone: each station less its UUV alone ---------------------------------------

# The product's increment with the viscous correction fitted for the model (`surrogate.viscous`).
CORRECTED = "flown + RANS correction"
INTERACTION_FIDELITIES = ("panel HF", "LF", "flown")


def uuv_alone(found: Iterable[rans.Result]) -> dict[tuple[float, ...], rans.Result]:
    """The converged UUV-alone results of the standard setup by (u_kn, psi_deg, d_ratio, ld_ratio)."""
    from nearsub.common.hydro.rans_campaign import free_stream_key

    return {
        free_stream_key(r.inputs): r
        for r in found
        if r.kind == "uuv-alone"
        and r.convergence.usable
        and r.inputs is not None
        and r.level == "medium"
        and standard_setup(r)
    }


def rans_interaction(results: list[rans.Result], alone: dict) -> np.ndarray:
    """(n, 3) RANS's interaction at each two-body result: its X', Y', N' less those of the same
    UUV alone at the same speed, heading and hull (NaN where that case is missing)."""
    from nearsub.common.hydro.rans_campaign import free_stream_key

    out = np.full((len(results), 3), np.nan)
    for i, r in enumerate(results):
        free = alone.get(free_stream_key(r.inputs))
        if free is not None:
            out[i] = [r.coefficients[k] - free.coefficients[k] for k in OUTPUTS]
    return out


def flown_increment(rows: np.ndarray, model, correction=None) -> np.ndarray:
    """(n, 3) the increment the product adds to (5.11) at configuration rows (n, 6), in
    coefficients (`interaction.lf_in_loop_increment`), with the viscous `correction` or without."""
    from types import SimpleNamespace

    from nearsub.common.hydro.low_fidelity import input_columns
    from nearsub.common.surrogate import interaction

    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    x, y, _, _, _, length = input_columns(rows)
    out = np.empty((len(rows), 3))
    table = interaction.increment_table(model)
    for i in range(len(rows)):  # one UUV each: every row its own hull
        # The vehicle's length only guards the LF table's reach 260 m off the hull (LF_MAX_LENGTH),
        # which a station beside it never needs: figure 4-4's 8.3 m UUV is compared as well.
        uuv = SimpleNamespace(name="station UUV", length=min(float(length[i]), interaction.LF_MAX_LENGTH))
        out[i] = interaction.lf_in_loop_increment(
            model, rows[i : i + 1], x[i : i + 1], y[i : i + 1], uuv, table, with_std=False, viscous=correction
        )[0][0]
    return out


def interaction_values(rows: np.ndarray, model, correction=None) -> dict[str, np.ndarray]:
    """Interaction [X', Y', N'] (n, 3) of each fidelity at rows (n, 6): the panel HF less its UUV
    alone, the LF less its own, the product's increment, and with a `correction` the increment
    with it (CORRECTED)."""
    from nearsub.common.hydro.high_fidelity import MEDIUM, hf_coefficients, hf_free_stream
    from nearsub.common.hydro.low_fidelity import lf_coefficients, lf_free_stream

    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    out = {
        "panel HF": np.asarray(hf_coefficients(rows, panels=MEDIUM), dtype=float) - hf_free_stream(rows, MEDIUM),
        "LF": np.asarray(lf_coefficients(rows), dtype=float) - lf_free_stream(rows),
        "flown": flown_increment(rows, model),
    }
    if correction is not None:
        out[CORRECTED] = flown_increment(rows, model, correction)
    return out


def correction_training(results: list[rans.Result], target: np.ndarray) -> tuple:
    """The stations a viscous correction is fitted on: medium mesh, not held out, with a RANS
    interaction. Returns their rows (m, 6), RANS's interaction there (m, 3) and their case ids."""
    keep = [
        i
        for i, r in enumerate(results)
        if r.level == "medium"
        and not ((s := station_of(r.inputs)) is not None and s.held_out)
        and np.all(np.isfinite(target[i]))
    ]
    rows = np.array([results[i].inputs for i in keep], dtype=float)
    return rows, target[keep], [results[i].case_id for i in keep]
