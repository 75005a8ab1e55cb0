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


def two_body_converged(found: Iterable[rans.Result]) -> list[rans.Result]:
    """The converged two-body results (the only ones compared), by R_long then the case id."""
    kept = [r for r in found if r.kind == "two-body" and r.convergence.usable and r.inputs is not None]
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


def comparison_rows(results: list[rans.Result], values: dict[str, np.ndarray]) -> list[dict]:
    """One row per RANS result: its station, X', Y', N', and for each fidelity in `values` (arrays
    (n, 3) in the order of `results`) its X', Y', N', the difference from RANS (other - RANS) and
    that difference relative to |RANS|."""
    out = []
    for i, r in enumerate(results):
        station = station_of(r.inputs)
        rans_values = np.array([r.coefficients[k] for k in OUTPUTS])
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
    the held-out rows (NaN where there are none), and how often the sign of each output agrees."""
    out = {}
    for name in fidelities:
        if not rows or name not in rows[0]:
            continue
        diff = np.array([r[f"{name} - RANS"] for r in rows], dtype=float)
        held = np.array([r["held_out"] for r in rows], dtype=bool)
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
