"""One-dimensional sweeps of the interaction coefficients: heading and lateral distance at a few
stations beside the submarine, the HF and LF physics and a surrogate side by side.

They show how the interaction behaves outside the surrogate's trained box (psi beyond +/-2 deg,
R_lat beyond constraint (4.5)), where the increment mode relies on the LF (docs/design.md,
"Physics decisions"). Stations are a nearsub choice: the SDV's hull (the large UUV of thesis
table 4.1) at the stern shoulder, midships and the bow shoulder, at 3 kn (about the thesis's
U_sub = 1.5 m/s, section 5.11.2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nearsub.common.hydro import high_fidelity, low_fidelity
from nearsub.common.physics.hull import L_SUB, R_SUB, uuv_dimensions

HEADINGS_DEG = np.arange(-20.0, 20.0 + 1e-9, 2.0)
MAX_HEADING_DEG = 20.0
TIP_MARGIN = 0.1  # [m] the heading sweep's tip clearance at |psi| = 20 deg (a nearsub choice)
LATERAL_POINTS = 15


@dataclass(frozen=True)
class Station:
    name: str
    r_long: float
    u_kn: float
    d_ratio: float
    ld_ratio: float

    @property
    def dimensions(self) -> tuple[float, float]:
        """(D_uuv, L_uuv) [m]."""
        diameter, length = uuv_dimensions(np.array([self.d_ratio]), np.array([self.ld_ratio]))
        return float(diameter[0]), float(length[0])


# SDV hull: D_sub / D_uuv = 10.363 / 0.53, L / D_uuv = 5.3 / 0.53 (physics/vehicles.py).
STATIONS = tuple(
    Station(name, r_long, 3.0, 19.553, 10.0)
    for name, r_long in (("stern shoulder", -0.35), ("midships", 0.0), ("bow shoulder", 0.35))
)


def heading_rows(station: Station) -> np.ndarray:
    """Inputs of the heading sweep: psi from -20 to 20 deg at the lateral distance where the UUV's
    tips clear the widest section by TIP_MARGIN at 20 deg."""
    diameter, length = station.dimensions
    y = R_SUB + 0.5 * diameter + 0.5 * length * math.sin(math.radians(MAX_HEADING_DEG)) + TIP_MARGIN
    rows = np.zeros((len(HEADINGS_DEG), 6))
    rows[:] = [station.r_long, y / L_SUB, station.u_kn, 0.0, station.d_ratio, station.ld_ratio]
    rows[:, 3] = HEADINGS_DEG
    return rows


def lateral_rows(station: Station) -> np.ndarray:
    """Inputs of the lateral sweep at psi = 0: the gap between the hulls from 5 cm to 4 D_uuv."""
    diameter, _ = station.dimensions
    gaps = np.geomspace(0.05, 4.0 * diameter, LATERAL_POINTS)
    rows = np.zeros((LATERAL_POINTS, 6))
    rows[:] = [station.r_long, 0.0, station.u_kn, 0.0, station.d_ratio, station.ld_ratio]
    rows[:, 1] = (R_SUB + 0.5 * diameter + gaps) / L_SUB
    return rows


def sweep_inputs() -> list[tuple[str, str, np.ndarray]]:
    """(station, sweep kind, inputs) for every sweep."""
    out = []
    for station in STATIONS:
        out.append((station.name, "heading", heading_rows(station)))
        out.append((station.name, "lateral", lateral_rows(station)))
    return out


def physics_increments(inputs: np.ndarray, panels=high_fidelity.MEDIUM) -> dict[str, np.ndarray]:
    """The interaction increment (coefficients minus the UUV alone at that speed and heading) of
    the HF and of the LF, (n, 3) each."""
    return {
        "hf": high_fidelity.hf_coefficients(inputs, panels) - high_fidelity.hf_free_stream(inputs, panels),
        "lf": low_fidelity.lf_coefficients(inputs) - low_fidelity.lf_free_stream(inputs),
    }


def applied_increments(model, inputs: np.ndarray, vehicle) -> np.ndarray:
    """The increment the sim applies in increment mode, [LF(x) - LF_free(x)] + w [delta(x_c) -
    (HF_free(x_c) - LF_free(x_c))] plus the model's viscous correction, in coefficients (n, 3)
    (`interaction.lf_in_loop_increment`; the hull ratios are the vehicle's)."""
    from nearsub.common.surrogate.interaction import increment_table, lf_in_loop_increment, viscous_correction

    x, y = inputs[:, 0] * L_SUB, inputs[:, 1] * L_SUB
    table, correction = increment_table(model), viscous_correction(model)
    increment, *_ = lf_in_loop_increment(model, inputs, x, y, vehicle, table, with_std=False, viscous=correction)
    return increment


# Stored sweep inputs against this machine's (`sweep_inputs`): the lateral gaps come from np.geomspace,
# whose last bits differ between CPUs (numpy's SIMD kernels); a changed sweep design moves them by far
# more than this.
INPUT_RTOL = 1e-12


def stored_hf(rows: list[dict], station: str, kind: str, inputs: np.ndarray) -> np.ndarray:
    """The HF increments (n, 3) of one sweep from the rows of an earlier sweeps.csv, whose inputs
    must be these to INPUT_RTOL (the HF does not change when a surrogate is retrained, so a new
    model's sweep need not run it again); ValueError naming the sweep otherwise."""
    names = ("R_long", "R_lat", "u_kn", "psi_deg", "d_ratio", "ld_ratio")
    try:
        mine = [r for r in rows if r["station"] == station and r["sweep"] == kind]
        stored = np.array([[float(r[n]) for n in names] for r in mine]).reshape(-1, 6)
        if stored.shape != inputs.shape or not np.allclose(stored, inputs, rtol=INPUT_RTOL, atol=0.0):
            raise ValueError(f"its {station} {kind} sweep has other inputs ({len(mine)} rows)")
        return np.array([[float(r[f"hf_{c}"]) for c in ("X_p", "Y_p", "N_p")] for r in mine])
    except KeyError as exc:
        raise ValueError(f"no column {exc}") from None


def sweep_table(model, vehicle, panels=high_fidelity.MEDIUM, hf_rows: list[dict] | None = None) -> list[dict]:
    """One row per sweep point: station, sweep, inputs, and the HF, LF and applied increments; the
    HF's taken from `hf_rows` (an earlier sweeps.csv at the same panels, `stored_hf`) when given."""
    names = ("R_long", "R_lat", "u_kn", "psi_deg", "d_ratio", "ld_ratio")
    rows = []
    for station, kind, inputs in sweep_inputs():
        if hf_rows is None:
            values = physics_increments(inputs, panels)
        else:
            lf = low_fidelity.lf_coefficients(inputs) - low_fidelity.lf_free_stream(inputs)
            values = {"hf": stored_hf(hf_rows, station, kind, inputs), "lf": lf}
        values["applied"] = applied_increments(model, inputs, vehicle)
        for i, point in enumerate(inputs):
            row = {"station": station, "sweep": kind, **dict(zip(names, point.tolist(), strict=True))}
            for source, array in values.items():
                row.update({f"{source}_{c}": float(array[i, j]) for j, c in enumerate(("X_p", "Y_p", "N_p"))})
            rows.append(row)
    return rows
