"""A surrogate input row as the dimensional case a CFD user sets up (for a CFD campaign: `nearsub campaign`).

The training campaign asks for high-fidelity samples at rows [R_long, R_lat, u_kn, psi_deg,
d_ratio, ld_ratio]; someone with real CFD needs hulls, lengths and positions in metres instead.
`case_geometry` gives them in the conventions of nearsub's own high fidelity (docs/hydro/README.md
"Conventions"), so that an answer in X', Y', N' means the same thing whoever computed it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from nearsub.common.hydro.low_fidelity import NU, input_columns
from nearsub.common.physics.hull import D_SUB, L_SUB, SUB_CB_FROM_NOSE, explorer_cb_from_nose
from nearsub.common.physics.proximity import closest_distance
from nearsub.common.surrogate.domain import INPUT_NAMES, KNOT, RHO_SEA

# Thesis section 4.4; the offsets are those of Groves, Huang and Chang (1989), DTRC/SHD-1298-01.
SUBMARINE_HULL = "DARPA SUBOFF bare hull (no sail or appendages) scaled to D = 34 ft"
UUV_HULL = "Explorer shape: bow ellipse over 2R (thesis (3.1)), cylinder, stern paraboloid over 4R (thesis (3.2))"
ANSWER_CONVENTION = (
    "UUV body axes, moments about the UUV's centre of buoyancy (its volume centroid); "
    "X' = X/(0.5 rho u^2 L_uuv^2), Y' = Y/(0.5 rho u^2 L_uuv^2), N' = N/(0.5 rho u^2 L_uuv^3); "
    "X' > 0 forward, Y' > 0 away from the submarine, N' > 0 turns the UUV's bow away from it"
)


def case_geometry(row: Any) -> dict[str, Any]:
    """The dimensional case of one input row (6,): hulls, sizes, positions [m], heading, speed, fluid.

    Frames (docs/design.md, "Frames, units and signs"; physics/hull.py): submarine frame with its
    origin at the submarine's centre of buoyancy (CB), x towards the bow; the UUV's CB at (x, y)
    with y > 0 on the UUV's side; both vehicles move at u through the water (thesis section 4.2.2,
    steady, quasi-static), so in the submarine frame the stream is -u along x and the UUV's bow is
    turned psi away from the submarine."""
    row = np.asarray(row, dtype=float).reshape(len(INPUT_NAMES))
    x, y, speed, psi, diameter, length = (float(column[0]) for column in input_columns(row[None, :]))
    return {
        "inputs": dict(zip(INPUT_NAMES, row.tolist(), strict=True)),
        "submarine": {
            "hull": SUBMARINE_HULL,
            "length_m": L_SUB,
            "diameter_m": D_SUB,
            "cb_behind_nose_m": SUB_CB_FROM_NOSE,
        },
        "uuv": {
            "hull": UUV_HULL,
            "length_m": length,
            "diameter_m": diameter,
            "cb_behind_nose_m": explorer_cb_from_nose(length, diameter),
        },
        "position": {
            "x_m": x,  # UUV CB ahead of the submarine's CB (R_long L_sub)
            "y_m": y,  # lateral, centre to centre (R_lat L_sub, docs/design.md, "Thesis errata" 7)
            "uuv_cb_behind_submarine_nose_m": SUB_CB_FROM_NOSE - x,
            "clearance_m": float(closest_distance(x, y, psi, length, diameter)),
        },
        "heading_deg": float(row[3]),
        "speed_m_s": speed,
        "speed_kn": speed / KNOT,
        "fluid": {"rho_kg_m3": RHO_SEA, "nu_m2_s": NU},
        "reynolds_uuv": speed * length / NU,
        "reynolds_submarine": speed * L_SUB / NU,
        "answer": ANSWER_CONVENTION,
    }
