"""RANS high fidelity on OpenFOAM (docs/hydro/rans/README.md): steady incompressible simpleFoam
with k-omega SST and wall functions, on a blockMesh background refined by snappyHexMesh with
boundary layers, in the half domain z >= 0 (the plane of both axes is a symmetry plane, thesis
section 3.3.3.1; a quarter domain for an axisymmetric case at zero drift).

A case is a `CaseSpec`: the bodies (rans_geometry.Body, from the project's hull profiles), the
stream, the fluid, the mesh level and the near-wall treatment. `write_case` writes the complete
OpenFOAM case with foamlib; `run_case` meshes and solves it (MPI with `cores` > 1) and returns a
`Result`: the forces on every body, X', Y', N' of the measured body nondimensionalised as the rest
of the project (docs/hydro/README.md, "Conventions"), and the convergence verdict.

Frames: the case frame is the submarine frame (origin at the submarine's CB, x towards the bow);
the stream is -U x. The measured body sits at (x, y) turned by psi (towards +y: away from the
submarine), so a single SUBOFF at drift angle psi sees the onset (-cos psi, sin psi) in its body
axes, exactly as high_fidelity.suboff_drift. Forces are taken in that body's axes, moments about
its CB.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from nearsub.common.hydro.high_fidelity import SUBOFF_TEST_NU, SUBOFF_TEST_SPEED
from nearsub.common.hydro.low_fidelity import NU, input_columns, ittc57
from nearsub.common.hydro.rans_geometry import Body, write_stl
from nearsub.common.physics.hull import D_SUB, FT, L_SUB, SUBOFF_LENGTH_FT, SUBOFF_RMAX_FT
from nearsub.common.physics.proximity import closest_distance

OPENFOAM_DIR = "/usr/share/openfoam"  # Debian's openfoam package (v1912); its etc/bashrc cannot be sourced
FRESH_WATER_RHO = 997.0  # thesis section 3.2 (tow-tank conditions of tables 3.1, 3.2)
SEA_WATER_RHO = 1025.0  # the two-body cases (docs/design.md, "Frames, units and signs")
CONFIGURATION = ("R_long", "R_lat", "u_kn", "psi_deg", "d_ratio", "ld_ratio")  # thesis table 4.2's order
SUBOFF_MODEL_LENGTH = SUBOFF_LENGTH_FT * FT  # 4.3561 m (Groves, Huang & Chang 1989)
SUBOFF_MODEL_DIAMETER = 2.0 * SUBOFF_RMAX_FT * FT  # 0.508 m
# Thesis table 3.1: SUBOFF bare hull at 3.05 m/s, EFD resistance (and the thesis's own CFD).
TABLE_3_1_EFD_X = -87.4  # [N]
TABLE_3_1_EFD_XPRIME = -9.95e-4
TABLE_3_1_CFD_X = -85.6  # [N]

# Inflow turbulence: 1 % intensity and an eddy-viscosity ratio of 10, common towing-tank RANS
# settings (nearsub's choice; `with_inflow` varies them, docs/hydro/rans/README.md "Inflow turbulence").
INFLOW_INTENSITY = 0.01
INFLOW_VISCOSITY_RATIO = 10.0
INFLOW_INTENSITY_RANGE = (1e-4, 0.2)  # accepted inputs (nearsub's bounds): 0.01 % to 20 %
INFLOW_VISCOSITY_RATIO_RANGE = (0.1, 1000.0)  # accepted inputs (nearsub's bounds)
# With `sustain_inflow`, k-omega SST's sustaining terms keep the inflow's k and omega from decaying
# on their way to the body (Spalart & Rumsey 2007, AIAA J. 45(10) 2544-2553; kOmegaSST's
# `decayControl` in OpenFOAM v1912): the bow then sees the inflow's 1 %, not about 0.2 %.
# Boundary layers: the first layer from a target y+ (at its cell centre) with u_tau from the
# ITTC-57 mean friction; 8 layers growing by 1.25 (the thesis grows its prism layers by 1.2,
# section 3.3.3.3; 1.25 reaches the outer cells with 8 layers).
LAYERS = 8
LAYER_EXPANSION = 1.25
# Below the log layer (a target y+ under 30: the buffer layer and the viscous sublayer, Pope 2000,
# "Turbulent Flows", table 7.1), the first layer is a hundredth (y+ 10) to a thousandth (y+ 1) of
# the surface cell it grows from; 8 layers by 1.25 stop far short of the outer cells and
# snappyHexMesh added none (docs/hydro/rans/README.md, "Resistance"). There the measured body's
# layers are the thesis's prism layers (section 3.3.3.3): growing by 1.2 until they span Prandtl's
# turbulent boundary-layer thickness at the body's end, 0.16 L / Re_L^(1/7) (thesis (3.10)). For
# SUBOFF at y+ 1: 37 layers, 15.6 um to 11 mm, 66 mm in all, the same at every mesh level (a stack
# of 30 ending at a fifth of the medium surface cell, 18.5 mm, gave a resistance 0.5 % higher).
LOG_LAYER_Y_PLUS = 30.0
RESOLVED_EXPANSION = 1.2
BOUNDARY_LAYER_COEFFICIENT = 0.16  # thesis (3.10)
# Such thin cells fail three of meshQualityDict's checks by their shape alone: the cell determinant
# (0.001; these cells: 3e-11 by `checkMesh -allGeometry`), the face-decomposition tet quality and,
# on the tapering stern, the face twist. snappyHexMesh removed their layers for these checks
# alone, so they are switched off (the "disable" values of OpenFOAM v1912's
# etc/caseDicts/meshQualityDict) in the `relaxed` set, used from the first layer iteration
# (nRelaxedIter 0), with the relaxed non-orthogonality of OpenFOAM's
# etc/caseDicts/mesh/generation/meshQualityDict.cfg (75: shrinking the mesh by the 66 mm stack
# skews a few hundred faces past 65). Castellation and snapping keep every check, the layers the
# others (skewness, face weights, volume ratios, pyramid volumes).
RESOLVED_LAYER_QUALITY = {"minDeterminant": -1.0, "minTetQuality": -1e30, "minTwist": -2.0, "maxNonOrtho": 75}
# The wall-function layers keep their thickness (their first cell is set by y+) while the mesh
# refines, so on the finer meshes the stack spans several surface cells (the UUV's 34 mm: 1.7 medium
# cells, 2.4 fine, 3.3 xfine) and shrinking the mesh away from the hull to make room for it
# inverted cells at the UUV's tail shoulder (the fine stern station: 6 negative volumes, 38
# illegal faces, simpleFoam's first pressure solve failed). Smoothing the shrinking displacement
# (snappyHexMesh's `nSmoothDisplacement`, 90 iterations as OpenFOAM's annotated
# snappyHexMeshDict suggests) gave that mesh no illegal face. It is used where the measured body's
# wall-function stack is thicker than SMOOTHED_STACK_CELLS of its surface cells; the meshes below
# that (every coarse and medium two-body case) are made as before.
SMOOTHED_STACK_CELLS = 2.0
SHRINK_SMOOTHING_ITERATIONS = 90
WALL_FUNCTIONS = {"nutk": "nutkWallFunction", "spalding": "nutUSpaldingWallFunction"}
# The turbulence model: k-omega SST (Menter 1994, AIAA J. 32(8) 1598-1605; OpenFOAM's kOmegaSST),
# or Wilcox's k-omega (Wilcox 1998, "Turbulence Modeling for CFD"; OpenFOAM's kOmega), the thesis's
# model (section 3.3.3.3), for any case (`--turbulence komega`). With the sublayer resolved (y+ 1, medium mesh) SST's
# friction was 72.4 N and k-omega's 77.7 N, against ITTC-57's 77.8 N (docs/hydro/rans/README.md).
TURBULENCE_MODELS = {"sst": "kOmegaSST", "komega": "kOmega"}
# The submarine beside a UUV is not measured: its first cell sits at y+ 300, still inside the log
# layer of its boundary layer (about 1 m thick at the stern at full scale, thesis (3.10)), so that
# its 8 layers reach its surface cells (0.3-0.5 m) without cells a hundred times smaller beside them.
OTHER_BODY_Y_PLUS = 300.0

# Convergence verdict: the spread (max - min) of each coefficient over the last 20 % of the
# iterations must stay within 1 % of its mean or 5e-6, whichever is larger (5e-6 is 4 % of the
# smallest EFD coefficient of thesis table 3.2, Y' = 1.34e-4 at 2.08 deg).
SPREAD_WINDOW = 0.2
SPREAD_RELATIVE = 0.01
SPREAD_ABSOLUTE = 5e-6
# A case whose measured body got fewer than half of its boundary layers is refused ("bad mesh"): its
# wall function then sits at whatever y+ the outer cells give.
MIN_LAYER_SHARE = 0.5
DIVERGED_COEFFICIENT = 0.1  # |X'|, |Y'| or |N'| above this is no flow round a hull (EFD: about 1e-3)
# A two-body case starts with first-order upwind for U over its first iterations, then continues
# with linearUpwind from there: from a uniform start at full scale (Re_sub about 1e8) linearUpwind
# blew up in the layer cells at the submarine's bow stagnation point within 10 iterations, under
# every relaxation tried (docs/hydro/rans/README.md, "The two-body divergence").
FIRST_ORDER_START = 50
# A case resolving its sublayer starts so too, for longer: on the medium SUBOFF mesh at y+ 1,
# linearUpwind from a uniform start blew up at iteration 49 in the layer cells 3 cm behind the bow
# (|U| 700 m/s at iteration 40); after 100 upwind iterations it ran on.
RESOLVED_FIRST_ORDER_START = 100
# The symmetry planes are OpenFOAM's `symmetry` patches, which take each face's own normal:
# snappyHexMesh's layers moved points of the z = 0 plane on the fine two-body mesh (1.09 M cells)
# off it, and simpleFoam refused the `symmetryPlane` type there ("not planar"). On a plane both
# types are the same condition.
SYMMETRY = "symmetry"


class CaseError(Exception):
    """A case that cannot be built or run; the text names the cause in one line."""


@dataclass(frozen=True)
class MeshLevel:
    """Background cells per reference length, and how many refinement levels the measured body's
    surface gets. The levels are fixed for a geometry and the background spacing is scaled by
    `scale`, so coarse/medium/fine refine every cell by the same ratio (sqrt 2), as a grid
    convergence study needs (Celik et al. 2008)."""

    name: str
    scale: float
    iterations: int


MESH_LEVELS = {
    "smoke": MeshLevel("smoke", 1.0, 100),  # the coarse background, one surface level less
    "coarse": MeshLevel("coarse", 1.0, 600),
    "medium": MeshLevel("medium", math.sqrt(2.0), 800),
    "fine": MeshLevel("fine", 2.0, 1000),
    # A fourth level for a grid study whose coarse/medium/fine changes are not yet in the asymptotic
    # range: the GCI of the medium/fine/xfine triplet (`rans_campaign.two_body_gci`).
    "xfine": MeshLevel("xfine", 2.0 * math.sqrt(2.0), 1200),
}
SURFACE_CELLS_PER_DIAMETER = 24  # at the coarse level (medium 34, fine 48, xfine 68) on the measured body


@dataclass(frozen=True)
class CaseSpec:
    """Everything that defines one RANS case. `bodies[0]` is the measured body (the UUV, or the
    SUBOFF model in the validation)."""

    case_id: str
    kind: str  # "suboff", "two-body" or "uuv-alone"
    bodies: tuple[Body, ...]
    speed: float  # [m/s], stream -speed x
    rho: float
    nu: float
    level: str = "medium"
    wall_function: str = "nutk"
    y_plus: float = 50.0
    quarter: bool = False  # a second symmetry plane y = 0 (axisymmetric body at zero drift)
    # the project's row for a two-body case; (u_kn, psi_deg, d_ratio, ld_ratio) for a UUV alone
    inputs: tuple[float, ...] | None = None
    iterations: int | None = None  # default: the level's
    sustain_inflow: bool = False  # SST's sustaining terms for the inflow turbulence (Spalart & Rumsey 2007)
    turbulence: str = "sst"  # a key of TURBULENCE_MODELS
    inflow_intensity: float = INFLOW_INTENSITY  # turbulence intensity at the inlet, a fraction
    inflow_viscosity_ratio: float = INFLOW_VISCOSITY_RATIO  # nu_t / nu at the inlet

    @property
    def body(self) -> Body:
        return self.bodies[0]

    @property
    def mesh_level(self) -> MeshLevel:
        return MESH_LEVELS[self.level]

    @property
    def end_iteration(self) -> int:
        return self.iterations or self.mesh_level.iterations

    @property
    def start_iterations(self) -> int:
        """Iterations solved with first-order upwind for U before the case's own schemes: a case
        resolving its sublayer RESOLVED_FIRST_ORDER_START, a SUBOFF case with wall functions none
        (stable without, and their validation was run so), the others FIRST_ORDER_START."""
        if resolves_sublayer(self):
            return min(RESOLVED_FIRST_ORDER_START, self.end_iteration // 4)
        return 0 if self.kind == "suboff" else min(FIRST_ORDER_START, self.end_iteration // 4)

    def describe(self) -> dict:
        out = asdict(self)
        out["bodies"] = [asdict(b) for b in self.bodies]
        return out


def _check_options(level: str, wall_function: str, y_plus: float) -> None:
    """The mesh level, wall function and target y+ of any case."""
    for name, value, choices in (("--level", level, MESH_LEVELS), ("--wall-function", wall_function, WALL_FUNCTIONS)):
        if value not in choices:
            raise CaseError(f"{name} {value!r}: choose one of {', '.join(choices)}")
    if not (math.isfinite(y_plus) and 1.0 <= y_plus <= 300.0):
        raise CaseError(f"--y-plus {y_plus!r}: wall functions need a first-cell y+ of about 1 to 300")


def _case_suffix(level: str, wall_function: str, y_plus: float, turbulence: str = "sst") -> str:
    suffix = f"-{level}"
    if wall_function != "nutk":
        suffix += f"-{wall_function}"
    if y_plus != 50.0:
        suffix += f"-yp{y_plus:g}"
    if turbulence != "sst":
        suffix += f"-{turbulence}"
    return suffix


def _check_turbulence(turbulence: str) -> None:
    if turbulence not in TURBULENCE_MODELS:
        raise CaseError(f"--turbulence {turbulence!r}: choose one of {', '.join(TURBULENCE_MODELS)}")


def suboff_case(
    psi_deg: float = 0.0,
    level: str = "medium",
    wall_function: str = "nutk",
    y_plus: float = 50.0,
    iterations: int | None = None,
    sustain_inflow: bool = False,
    turbulence: str = "sst",
) -> CaseSpec:
    """The model-scale SUBOFF bare hull alone at drift angle psi_deg in the tow-tank conditions of
    thesis tables 3.1/3.2 (3.05 m/s, fresh water, nu = 8.899e-4/997): the validation case."""
    _check_options(level, wall_function, y_plus)
    if not (math.isfinite(psi_deg) and 0.0 <= psi_deg <= 20.0):
        raise CaseError(f"--psi {psi_deg!r}: the validation covers drift angles 0 to 20 deg")
    _check_turbulence(turbulence)
    if sustain_inflow and turbulence != "sst":
        raise CaseError(f"--sustain-inflow: SST's sustaining terms, not for --turbulence {turbulence}")
    hull = Body("suboff", "suboff-model", SUBOFF_MODEL_LENGTH, SUBOFF_MODEL_DIAMETER, psi=math.radians(psi_deg))
    return CaseSpec(
        case_id=f"suboff-psi{psi_deg:.2f}"
        + _case_suffix(level, wall_function, y_plus, turbulence)
        + ("-sust" if sustain_inflow else ""),
        kind="suboff",
        bodies=(hull,),
        speed=SUBOFF_TEST_SPEED,
        rho=FRESH_WATER_RHO,
        nu=SUBOFF_TEST_NU,
        level=level,
        wall_function=wall_function,
        y_plus=y_plus,
        quarter=psi_deg == 0.0,
        iterations=iterations,
        sustain_inflow=sustain_inflow,
        turbulence=turbulence,
    )


def _configuration(row, level: str, wall_function: str, y_plus: float) -> tuple[np.ndarray, tuple[float, ...]]:
    """A checked configuration row (6,) and its dimensional x, y [m], speed [m/s], psi [rad],
    diameter and length [m] (`low_fidelity.input_columns`); CaseError names what is wrong."""
    _check_options(level, wall_function, y_plus)
    row = np.asarray(row, dtype=float).reshape(-1)
    if row.shape != (len(CONFIGURATION),) or not np.all(np.isfinite(row)):
        raise CaseError(f"configuration {row.tolist()}: needs 6 finite values {', '.join(CONFIGURATION)}")
    columns = tuple(float(c[0]) for c in input_columns(row[None, :]))
    if not columns[2] > 0:
        raise CaseError(f"u_kn {row[2]:g}: the speed must be positive")
    if columns[5] < 3.0 * columns[4]:
        raise CaseError(f"ld_ratio {row[5]:g}: the Explorer hull needs L/D >= 3")
    return row, columns


def two_body_case(
    row,
    level: str = "medium",
    wall_function: str = "nutk",
    y_plus: float = 50.0,
    iterations: int | None = None,
    turbulence: str = "sst",
) -> CaseSpec:
    """The full-scale submarine and the Explorer UUV at a configuration row [R_long, R_lat, u_kn,
    psi_deg, d_ratio, ld_ratio] (thesis table 4.2), in sea water (docs/hydro/README.md)."""
    row, (x, y, speed, psi, diameter, length) = _configuration(row, level, wall_function, y_plus)
    _check_turbulence(turbulence)
    if y <= 0:
        raise CaseError(f"R_lat {row[1]:g}: the UUV sits on the +y side of the submarine (R_lat > 0)")
    clearance = float(closest_distance(x, y, psi, length, diameter))
    # The mesher needs a few surface cells between the hulls: refuse a gap under a fifth of a UUV
    # diameter (touching or overlapping hulls included).
    if clearance < 0.2 * diameter:
        raise CaseError(
            f"configuration R_long={row[0]:g} R_lat={row[1]:g} psi={row[3]:g}: hull clearance {clearance:.3f} m is "
            f"below a fifth of the UUV diameter ({0.2 * diameter:.3f} m): the mesher cannot build it"
        )
    uuv = Body("uuv", "explorer", length, diameter, x, y, psi)
    sub = Body("submarine", "suboff-full", L_SUB, D_SUB)
    return _sea_water_case(
        "two-body", "tb-", row, (uuv, sub), speed, False, level, wall_function, y_plus, iterations, turbulence
    )


def uuv_alone_case(
    row,
    level: str = "medium",
    wall_function: str = "nutk",
    y_plus: float = 50.0,
    iterations: int | None = None,
    turbulence: str = "sst",
) -> CaseSpec:
    """The Explorer UUV of a two-body configuration row alone, at the row's speed, heading and hull
    (u_kn, psi_deg, d_ratio, ld_ratio; R_long and R_lat are ignored), with the same water, mesh
    level and wall treatment: its forces are the free-stream part of the two-body case's, so that
    the two give the interaction alone (`rans_comparison`). A quarter domain at zero heading."""
    row, (_, _, speed, psi, diameter, length) = _configuration(row, level, wall_function, y_plus)
    _check_turbulence(turbulence)
    uuv = Body("uuv", "explorer", length, diameter, 0.0, 0.0, psi)
    return _sea_water_case(
        "uuv-alone", "uuv-", row[2:], (uuv,), speed, psi == 0.0, level, wall_function, y_plus, iterations, turbulence
    )


def _sea_water_case(
    kind: str,
    prefix: str,
    values: np.ndarray,
    bodies: tuple[Body, ...],
    speed: float,
    quarter: bool,
    level: str,
    wall_function: str,
    y_plus: float,
    iterations: int | None,
    turbulence: str,
) -> CaseSpec:
    """A case in the two-body cases' sea water, named by its configuration values and treatment."""
    return CaseSpec(
        case_id=prefix + "_".join(f"{v:g}" for v in values) + _case_suffix(level, wall_function, y_plus, turbulence),
        kind=kind,
        bodies=bodies,
        speed=speed,
        rho=SEA_WATER_RHO,
        nu=NU,
        level=level,
        wall_function=wall_function,
        y_plus=y_plus,
        quarter=quarter,
        inputs=tuple(values.tolist()),
        iterations=iterations,
        turbulence=turbulence,
    )


# --- the case's numbers ------------------------------------------------------------------------


def first_layer_thickness(spec: CaseSpec, body: Body | None = None) -> float:
    """First boundary-layer cell height [m] of a body (default: the measured one) for its target
    y+ at the cell centre: the case's y+ on the measured body, OTHER_BODY_Y_PLUS on the others;
    u_tau = U sqrt(C_F / 2) from the body's ITTC-57 mean friction coefficient."""
    body = body or spec.body
    y_plus = spec.y_plus if body is spec.body else OTHER_BODY_Y_PLUS
    cf = float(ittc57(spec.speed * body.length / spec.nu))
    u_tau = spec.speed * math.sqrt(0.5 * cf)
    return 2.0 * y_plus * spec.nu / u_tau


def resolves_sublayer(spec: CaseSpec) -> bool:
    """The measured body's first cell sits below the log layer (LOG_LAYER_Y_PLUS)."""
    return spec.y_plus < LOG_LAYER_Y_PLUS


def boundary_layer_thickness(spec: CaseSpec) -> float:
    """Prandtl's turbulent boundary-layer thickness [m] at the measured body's end (thesis (3.10))."""
    reynolds = spec.speed * spec.body.length / spec.nu
    return BOUNDARY_LAYER_COEFFICIENT * spec.body.length / reynolds ** (1.0 / 7.0)


def boundary_layers(spec: CaseSpec) -> tuple[int, float]:
    """(layers, expansion ratio) on the measured body: LAYERS by LAYER_EXPANSION, or below the log
    layer as many layers growing by RESOLVED_EXPANSION as span `boundary_layer_thickness`. Other
    bodies always get LAYERS by LAYER_EXPANSION."""
    if not resolves_sublayer(spec):
        return LAYERS, LAYER_EXPANSION
    r = RESOLVED_EXPANSION
    growth = 1.0 + boundary_layer_thickness(spec) * (r - 1.0) / first_layer_thickness(spec)  # r^n
    return max(LAYERS, round(math.log(growth) / math.log(r))), r


def layer_stack_cells(spec: CaseSpec, dom: Domain) -> float:
    """The measured body's boundary-layer stack, in its surface cells."""
    count, expansion = boundary_layers(spec)
    stack = first_layer_thickness(spec) * (expansion**count - 1.0) / (expansion - 1.0)
    return stack / (dom.background / 2 ** dom.surface_levels[0])


@dataclass(frozen=True)
class Domain:
    lo: np.ndarray
    hi: np.ndarray
    cells: tuple[int, int, int]
    surface_levels: tuple[int, ...]  # per body
    background: float  # background cell size [m]


def domain(spec: CaseSpec) -> Domain:
    """The box: one longest-body length ahead, above and to the sides, three behind (thesis section
    3.3.3.1, after the ITTC); z >= 0 (and y >= 0 for a quarter domain). Background cells of a
    twelfth of the longest body's length at the coarse level; each body's surface gets the
    refinement level nearest to SURFACE_CELLS_PER_DIAMETER cells per diameter."""
    boxes = [b.bounds() for b in spec.bodies]
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    reach = max(b.length for b in spec.bodies)
    lo = lo - np.array([3.0 * reach, reach, 0.0])
    hi = hi + np.array([reach, reach, reach])
    lo[2] = 0.0
    if spec.quarter:
        lo[1] = 0.0
    coarse = reach / 12.0
    surface = [max(0, round(math.log2(coarse / (b.diameter / SURFACE_CELLS_PER_DIAMETER)))) for b in spec.bodies]
    background = coarse / spec.mesh_level.scale
    if spec.level == "smoke":
        surface = [max(0, s - 1) for s in surface]
    cells = tuple(int(math.ceil((high - low) / background)) for low, high in zip(lo, hi, strict=True))
    return Domain(lo, hi, cells, tuple(surface), background)


def inflow_turbulence(spec: CaseSpec) -> tuple[float, float]:
    """k and omega at the inlet from the case's intensity I and eddy-viscosity ratio:
    k = 1.5 (I U)^2, omega = k / (ratio nu)."""
    k = 1.5 * (spec.inflow_intensity * spec.speed) ** 2
    return k, k / (spec.inflow_viscosity_ratio * spec.nu)


def with_inflow(spec: CaseSpec, intensity: float, viscosity_ratio: float) -> CaseSpec:
    """The same case with another inflow turbulence (intensity a fraction, nu_t/nu); a case id
    that names it (`-tu<percent>-vr<ratio>`) unless it is the default."""
    for name, value, (low, high), scale in (
        ("--inflow-intensity", intensity, INFLOW_INTENSITY_RANGE, 100.0),
        ("--inflow-viscosity-ratio", viscosity_ratio, INFLOW_VISCOSITY_RATIO_RANGE, 1.0),
    ):
        if not (math.isfinite(value) and low <= value <= high):
            raise CaseError(f"{name} {value * scale!r}: choose {low * scale:g} to {high * scale:g}")
    if intensity == spec.inflow_intensity and viscosity_ratio == spec.inflow_viscosity_ratio:
        return spec
    suffix = f"-tu{100.0 * intensity:g}-vr{viscosity_ratio:g}"
    return replace(
        spec, case_id=spec.case_id + suffix, inflow_intensity=intensity, inflow_viscosity_ratio=viscosity_ratio
    )


# --- writing the case --------------------------------------------------------------------------


def _write(path: Path, entries: dict, field_class: str | None = None) -> None:
    from foamlib import FoamFieldFile, FoamFile

    path.parent.mkdir(parents=True, exist_ok=True)
    path.unlink(missing_ok=True)
    path.touch()
    f = FoamFieldFile(path) if field_class else FoamFile(path)
    with f:
        if field_class:
            f["FoamFile"] = {"version": 2.0, "format": "ascii", "class": field_class, "object": path.name}
        f.update(entries)


def _vec(v) -> list[float]:
    return [float(round(c, 9)) for c in v]


def _block_mesh(spec: CaseSpec, dom: Domain) -> dict:
    (x0, y0, z0), (x1, y1, z1) = dom.lo, dom.hi
    vertices = [
        [x0, y0, z0],
        [x1, y0, z0],
        [x1, y1, z0],
        [x0, y1, z0],
        [x0, y0, z1],
        [x1, y0, z1],
        [x1, y1, z1],
        [x0, y1, z1],
    ]
    patches = [
        ("inlet", {"type": "patch", "faces": [[1, 2, 6, 5]]}),  # +x: the stream comes from ahead
        ("outlet", {"type": "patch", "faces": [[0, 4, 7, 3]]}),
        ("symmetryZ", {"type": SYMMETRY, "faces": [[0, 3, 2, 1]]}),
        ("top", {"type": "patch", "faces": [[4, 5, 6, 7]]}),
        ("sideFar", {"type": "patch", "faces": [[3, 7, 6, 2]]}),
    ]
    near_side = ("sideNear", {"type": "patch", "faces": [[0, 1, 5, 4]]})
    if spec.quarter:
        near_side = ("symmetryY", {"type": SYMMETRY, "faces": [[0, 1, 5, 4]]})
    patches.append(near_side)
    return {
        "scale": 1,
        "vertices": [_vec(v) for v in vertices],
        "blocks": ["hex", list(range(8)), list(dom.cells), "simpleGrading", [1, 1, 1]],
        "edges": [],
        "boundary": patches,
        "mergePatchPairs": [],
    }


def far_patches(spec: CaseSpec) -> list[str]:
    return ["top", "sideFar"] + ([] if spec.quarter else ["sideNear"])


def symmetry_patches(spec: CaseSpec) -> list[str]:
    return ["symmetryZ"] + (["symmetryY"] if spec.quarter else [])


def _snappy(spec: CaseSpec, dom: Domain) -> dict:
    geometry, surfaces, regions, layers = {}, {}, {}, {}
    for body, level in zip(spec.bodies, dom.surface_levels, strict=True):
        geometry[f"{body.patch}.stl"] = {"type": "triSurfaceMesh", "name": body.patch}
        # One level more where the surface curves more than 30 deg within a cell (the tips).
        surfaces[body.patch] = {"level": [level, level + 1], "patchInfo": {"type": "wall"}}
        near = body.diameter
        shells = [[0.5 * near, max(level - 1, 0)], [2 * near, max(level - 2, 0)]]
        if body.diameter < dom.background:
            # Refinement by surface intersection loses a body thinner than a background cell as
            # the cells shrink (edges stop cutting it); a thin shell at the surface level carries
            # it to its level.
            shells.insert(0, [0.15 * near, level])
        regions[body.patch] = {"mode": "distance", "levels": shells}
        first = first_layer_thickness(spec, body)
        count, expansion = boundary_layers(spec) if body is spec.body else (LAYERS, LAYER_EXPANSION)
        layers[body.patch] = {
            "nSurfaceLayers": count,
            "expansionRatio": expansion,
            "firstLayerThickness": float(f"{first:.4g}"),
            "minThickness": float(f"{0.1 * first:.4g}"),
        }
    # The measured body's wake: one level below its surface level, half a length behind it, and
    # a box round it two levels below.
    body, level = spec.body, dom.surface_levels[0]
    lo, hi = body.bounds()
    pad = 0.5 * body.diameter
    geometry["wake"] = {
        "type": "searchableBox",
        "min": _vec(lo - [0.5 * body.length, pad, 0.0]),
        "max": _vec(hi + [pad, pad, pad]),
    }
    geometry["around"] = {
        "type": "searchableBox",
        "min": _vec(lo - [1.5 * body.length, 4 * pad, 0.0]),
        "max": _vec(hi + [0.5 * body.length, 4 * pad, 4 * pad]),
    }
    regions["wake"] = {"mode": "inside", "levels": [[1e15, max(level - 2, 0)]]}
    regions["around"] = {"mode": "inside", "levels": [[1e15, max(level - 3, 0)]]}
    inside = dom.lo + (dom.hi - dom.lo) * np.array([0.0123, 0.9071, 0.9137])  # a far corner, in the fluid
    quality = dict(MESH_QUALITY)
    layer_options = {}
    if resolves_sublayer(spec):
        quality["relaxed"] = dict(RESOLVED_LAYER_QUALITY)
        layer_options = {"nRelaxedIter": 0}
    elif layer_stack_cells(spec, dom) > SMOOTHED_STACK_CELLS:
        layer_options = {"nSmoothDisplacement": SHRINK_SMOOTHING_ITERATIONS}
    return {
        "castellatedMesh": True,
        "snap": True,
        "addLayers": True,
        "geometry": geometry,
        "castellatedMeshControls": {
            "maxLocalCells": 4_000_000,
            "maxGlobalCells": 8_000_000,
            "minRefinementCells": 0,
            "maxLoadUnbalance": 0.10,
            "nCellsBetweenLevels": 3,
            "features": [],
            "refinementSurfaces": surfaces,
            "resolveFeatureAngle": 30,
            "refinementRegions": regions,
            "locationInMesh": _vec(inside),
            "allowFreeStandingZoneFaces": True,
        },
        "snapControls": {
            "nSmoothPatch": 3,
            "tolerance": 2.0,
            "nSolveIter": 100,
            "nRelaxIter": 5,
            "nFeatureSnapIter": 10,
            "implicitFeatureSnap": False,
            "explicitFeatureSnap": False,
            "multiRegionFeatureSnap": False,
        },
        "addLayersControls": {
            "relativeSizes": False,
            "layers": layers,
            "expansionRatio": boundary_layers(spec)[1],
            "firstLayerThickness": float(f"{first_layer_thickness(spec):.4g}"),
            "minThickness": float(f"{0.1 * first_layer_thickness(spec):.4g}"),
            "nGrow": 0,
            "featureAngle": 130,
            "slipFeatureAngle": 30,
            "nRelaxIter": 3,
            "nSmoothSurfaceNormals": 1,
            "nSmoothNormals": 3,
            "nSmoothThickness": 10,
            "maxFaceThicknessRatio": 0.5,
            "maxThicknessToMedialRatio": 0.3,
            "minMedialAxisAngle": 90,
            "nBufferCellsNoExtrude": 0,
            "nLayerIter": 50,
            **layer_options,
        },
        "meshQualityControls": quality,
        "mergeTolerance": 1e-6,
    }


MESH_QUALITY = {  # the values of OpenFOAM's etc/caseDicts/meshQualityDict
    "maxNonOrtho": 65,
    "maxBoundarySkewness": 20,
    "maxInternalSkewness": 4,
    "maxConcave": 80,
    "minVol": 1e-13,
    "minTetQuality": 1e-15,
    "minArea": -1,
    "minTwist": 0.02,
    "minDeterminant": 0.001,
    "minFaceWeight": 0.05,
    "minVolRatio": 0.01,
    "minTriangleTwist": -1,
    "nSmoothScale": 4,
    "errorReduction": 0.75,
}


# The solver writes its fields every CHECKPOINT_ITERATIONS, or every fifth of a shorter run
# (keeping only the latest), so a run stopped by an interruption goes on from there when the case
# is run again (`run_case`). A write costs a second or two on a fine two-body mesh (about 100 MB).
CHECKPOINT_ITERATIONS = 100


def _control(spec: CaseSpec, end: int | None = None, restart: bool = False) -> dict:
    """controlDict: run to `end` (default the case's last iteration), from the latest time with
    `restart` (the second stage after a first-order start)."""
    functions = {}
    for body in spec.bodies:
        functions[f"forces_{body.patch}"] = {
            "type": "forces",
            "libs": ["libforces.so"],
            "writeControl": "timeStep",
            "writeInterval": 1,
            "patches": [body.patch],
            "rho": "rhoInf",
            "rhoInf": spec.rho,
            "CofR": _vec(body.centre),
            "log": False,
        }
    functions["yPlus"] = {"type": "yPlus", "libs": ["libfieldFunctionObjects.so"], "writeControl": "writeTime"}
    n = end or spec.end_iteration
    return {
        "application": "simpleFoam",
        "startFrom": "latestTime" if restart else "startTime",
        "startTime": 0,
        "stopAt": "endTime",
        "endTime": n,
        "deltaT": 1,
        "writeControl": "timeStep",
        "writeInterval": min(CHECKPOINT_ITERATIONS, max(1, n // 5)),
        "purgeWrite": 1,
        "writeFormat": "binary",
        "writePrecision": 8,
        "writeCompression": False,
        "timeFormat": "general",
        "timePrecision": 6,
        "runTimeModifiable": False,
        "functions": functions,
    }


FV_SCHEMES = {
    "ddtSchemes": {"default": "steadyState"},
    "gradSchemes": {"default": "Gauss linear", "grad(U)": "cellLimited Gauss linear 1"},
    "divSchemes": {
        "default": "none",
        "div(phi,U)": "bounded Gauss linearUpwind grad(U)",
        "div(phi,k)": "bounded Gauss upwind",
        "div(phi,omega)": "bounded Gauss upwind",
        "div((nuEff*dev2(T(grad(U)))))": "Gauss linear",
    },
    "laplacianSchemes": {"default": "Gauss linear limited corrected 0.33"},
    "interpolationSchemes": {"default": "linear"},
    "snGradSchemes": {"default": "limited corrected 0.33"},
    "wallDist": {"method": "meshWave"},
}

# The first-order start (FIRST_ORDER_START): upwind for U as well.
FIRST_ORDER_SCHEMES = FV_SCHEMES | {
    "divSchemes": FV_SCHEMES["divSchemes"] | {"div(phi,U)": "bounded Gauss upwind"},
}

FV_SOLUTION = {
    "solvers": {
        "p": {"solver": "GAMG", "smoother": "GaussSeidel", "tolerance": 1e-7, "relTol": 0.1},
        "(U|k|omega)": {
            "solver": "smoothSolver",
            "smoother": "symGaussSeidel",
            "tolerance": 1e-8,
            "relTol": 0.1,
            "nSweeps": 1,
        },
    },
    "SIMPLE": {
        "nNonOrthogonalCorrectors": 0,
        "consistent": True,
        "residualControl": {"p": 1e-4, "U": 1e-5, "(k|omega)": 1e-5},
    },
    "relaxationFactors": {"equations": {"U": 0.9, ".*": 0.7}},
}

# A case whose forces had not settled when residual control stopped it (about 150-230 iterations on
# the two-body stations, with p's residual at 1e-4) is continued from there without residual
# control, to its level's last iteration.
FV_SOLUTION_TO_END = FV_SOLUTION | {
    "SIMPLE": {k: v for k, v in FV_SOLUTION["SIMPLE"].items() if k != "residualControl"}
}


def _token(word: str):
    try:
        return int(word)
    except ValueError:
        try:
            return float(word)
        except ValueError:
            return word


def _foam_entries(entries: dict) -> dict:
    """Scheme-style entries as foamlib writes them: a value of several words becomes a tuple of
    tokens (foamlib refuses a string with spaces), and a regular-expression key gets its quotes
    (foamlib writes keys as given)."""
    out = {}
    for key, value in entries.items():
        if isinstance(value, dict):
            value = _foam_entries(value)
        elif isinstance(value, str) and " " in value:
            value = tuple(_token(w) for w in value.split())
        out[f'"{key}"' if any(c in key for c in "|*") and not key.startswith(("div", "grad")) else key] = value
    return out


def _fields(spec: CaseSpec) -> dict[str, tuple[str, dict]]:
    """The 0/ files: uniform start (potentialFoam is not used: docs/hydro/rans/README.md)."""
    from foamlib import FoamFieldFile

    u = np.array([-spec.speed, 0.0, 0.0])
    k, omega = inflow_turbulence(spec)
    nut_wall = WALL_FUNCTIONS[spec.wall_function]
    walls = [b.patch for b in spec.bodies]
    far, sym = far_patches(spec), symmetry_patches(spec)
    proc = '"procBoundary.*"'  # the processor patches of a decomposed case

    def boundary(inlet, outlet, wall, internal):
        out = {"inlet": inlet, "outlet": outlet}
        out |= {p: {"type": "slip"} for p in far}
        out |= {p: {"type": SYMMETRY} for p in sym}
        out |= {w: dict(wall) for w in walls}
        out[proc] = {"type": "processor", "value": internal}
        return out

    dims = FoamFieldFile.DimensionSet
    fields = {
        "U": (
            "volVectorField",
            dims(length=1, time=-1),
            u,
            boundary(
                {"type": "fixedValue", "value": u},
                {"type": "inletOutlet", "inletValue": np.zeros(3), "value": u},
                {"type": "noSlip"},
                u,
            ),
        ),
        "p": (
            "volScalarField",
            dims(length=2, time=-2),
            0.0,
            boundary({"type": "zeroGradient"}, {"type": "fixedValue", "value": 0.0}, {"type": "zeroGradient"}, 0.0),
        ),
        "k": (
            "volScalarField",
            dims(length=2, time=-2),
            k,
            boundary(
                {"type": "fixedValue", "value": k},
                {"type": "inletOutlet", "inletValue": k, "value": k},
                {"type": "kqRWallFunction", "value": k},
                k,
            ),
        ),
        "omega": (
            "volScalarField",
            dims(time=-1),
            omega,
            boundary(
                {"type": "fixedValue", "value": omega},
                {"type": "inletOutlet", "inletValue": omega, "value": omega},
                {"type": "omegaWallFunction", "value": omega},
                omega,
            ),
        ),
        "nut": (
            "volScalarField",
            dims(length=2, time=-1),
            0.0,
            boundary(
                {"type": "calculated", "value": 0.0},
                {"type": "calculated", "value": 0.0},
                {"type": nut_wall, "value": 0.0},
                0.0,
            ),
        ),
    }
    return {
        name: (cls, {"dimensions": d, "internalField": v, "boundaryField": b})
        for name, (cls, d, v, b) in fields.items()
    }


def write_case(spec: CaseSpec, folder, cores: int = 1) -> Path:
    """Write the complete case into `folder` (created; an existing case there is replaced): the
    STL of every body, system/ (blockMesh, snappyHexMesh, controlDict with the forces and yPlus
    function objects, schemes, solution, decomposition), constant/ (transport, turbulence) and
    the initial fields in 0.orig/ (copied to 0/ after meshing), and case.json (the spec)."""
    folder = Path(folder)
    if folder.exists():
        shutil.rmtree(folder)
    (folder / "constant" / "triSurface").mkdir(parents=True)
    dom = domain(spec)
    for body in spec.bodies:
        write_stl(folder / "constant" / "triSurface" / f"{body.patch}.stl", body.triangles(), body.patch)
    system = folder / "system"
    _write(system / "blockMeshDict", _block_mesh(spec, dom))
    _write(system / "snappyHexMeshDict", _snappy(spec, dom))
    _write(system / "controlDict", _control(spec))
    _write(system / "fvSchemes", _foam_entries(FV_SCHEMES))
    _write(system / "fvSolution", _foam_entries(FV_SOLUTION))
    _write(
        system / "decomposeParDict",
        {"numberOfSubdomains": cores, "method": "hierarchical", "coeffs": {"n": [cores, 1, 1]}},
    )
    _write(folder / "constant" / "transportProperties", {"transportModel": "Newtonian", "nu": spec.nu})
    ras = {"RASModel": TURBULENCE_MODELS[spec.turbulence], "turbulence": True, "printCoeffs": True}
    if spec.sustain_inflow:
        k, omega = inflow_turbulence(spec)
        ras["kOmegaSSTCoeffs"] = {"decayControl": True, "kInf": k, "omegaInf": omega}
    _write(folder / "constant" / "turbulenceProperties", {"simulationType": "RAS", "RAS": ras})
    for name, (cls, entries) in _fields(spec).items():
        _write(folder / "0.orig" / name, entries, field_class=cls)
    (folder / "case.json").write_text(json.dumps(spec.describe(), indent=1) + "\n")
    return folder


def load_spec(folder) -> CaseSpec:
    """The spec a case folder was written from (its case.json)."""
    data = json.loads((Path(folder) / "case.json").read_text())
    data["bodies"] = tuple(Body(**b) for b in data["bodies"])
    if data.get("inputs") is not None:
        data["inputs"] = tuple(data["inputs"])
    return CaseSpec(**data)


# --- running -----------------------------------------------------------------------------------


def openfoam_environment() -> None:
    """What Debian's OpenFOAM needs in the environment of its tools (foamlib passes ours on):
    WM_PROJECT_DIR (the package's etc/bashrc cannot be sourced), and, as root, Open MPI's consent."""
    os.environ.setdefault("WM_PROJECT_DIR", OPENFOAM_DIR)
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
        os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")


def openfoam_missing() -> str | None:
    """Why OpenFOAM cannot run here (one line), or None."""
    install = "install Debian's package: apt-get install openfoam"
    for tool in ("blockMesh", "snappyHexMesh", "simpleFoam", "decomposePar", "mpiexec"):
        if shutil.which(tool) is None:
            return f"OpenFOAM is not installed ({tool} not found); {install}"
    if not Path(OPENFOAM_DIR, "etc", "controlDict").is_file():
        return f"OpenFOAM's etc/controlDict is missing under {OPENFOAM_DIR}; {install}"
    return None


@dataclass
class Convergence:
    status: str  # "converged", "not converged", "diverged" or "bad mesh"
    reason: str
    iterations: int
    window: int
    spread: dict[str, float]
    residuals: dict[str, float]

    @property
    def usable(self) -> bool:
        return self.status == "converged"


@dataclass
class Result:
    case_id: str
    kind: str
    level: str
    wall_function: str
    y_plus_target: float
    cells: int
    cores: int
    mesh_seconds: float
    solve_seconds: float
    coefficients: dict[str, float]  # X', Y', N' of the measured body, mean over the window
    forces: dict[str, dict[str, float]]  # per patch: X, Y [N], N [N m] whole body, body axes, about its CB
    convergence: Convergence
    y_plus: dict[str, dict[str, float]] = field(default_factory=dict)
    inputs: tuple[float, ...] | None = None
    openfoam: str = ""
    # the case's turbulence model and inflow (results written before these were recorded: `results`
    # reads them from the case's case.json)
    turbulence: str = "sst"
    inflow_intensity: float = INFLOW_INTENSITY
    inflow_viscosity_ratio: float = INFLOW_VISCOSITY_RATIO

    @property
    def wall_seconds(self) -> float:
        return self.mesh_seconds + self.solve_seconds

    def to_json(self) -> dict:
        out = asdict(self)
        out["wall_seconds"] = self.wall_seconds
        return out

    @classmethod
    def from_json(cls, data: dict) -> Result:
        data = dict(data)
        data.pop("wall_seconds", None)
        data["convergence"] = Convergence(**data["convergence"])
        if data.get("inputs") is not None:
            data["inputs"] = tuple(data["inputs"])
        return cls(**data)

    def line(self) -> str:
        c = self.coefficients
        return (
            f"{self.case_id}: {self.convergence.status}; X'={c['X']:.4e} Y'={c['Y']:.4e} N'={c['N']:.4e}; "
            f"{self.cells} cells, {self.wall_seconds / 60:.1f} min on {self.cores} cores"
        )


def _run(case, cmd: list[str], cores: int, parallel: bool) -> None:
    from foamlib._cases._subprocess import CalledProcessError  # foamlib's subclass of subprocess's

    try:
        case.run(cmd, parallel=parallel, cpus=cores if parallel else 1, check=True, log=True)
    except (CalledProcessError, subprocess.CalledProcessError) as exc:
        log = Path(case.path) / f"log.{cmd[0]}"
        raise CaseError(f"{cmd[0]} failed (exit {exc.returncode}): {_fatal_line(log)}; see {log}") from None


def _fatal_line(log: Path) -> str:
    """What stopped a tool: the line after OpenFOAM's 'FOAM FATAL' banner, or a signal an MPI rank
    died of (a floating-point exception when the solution blew up), or the log's last words."""
    try:
        lines = [ln.strip() for ln in log.read_text(errors="replace").splitlines() if ln.strip(" -\n")]
    except OSError:
        return "no log"
    for i, ln in enumerate(lines):
        if "FOAM FATAL" in ln:
            return " ".join(lines[i + 1 : i + 3])[:300]
    for ln in lines:
        if "exited on signal" in ln:
            return ln[ln.index("exited on signal") :][:300]
    return lines[-1][:300] if lines else "empty log"


def mesh_case(folder, cores: int = 1) -> int:
    """blockMesh, decomposition and snappyHexMesh (-overwrite), then the initial fields in place;
    returns the cell count."""
    from foamlib import FoamCase

    openfoam_environment()
    folder = Path(folder)
    case = FoamCase(folder)
    parallel = cores > 1
    for stale in [*folder.glob("processor*"), folder / "0", folder / "postProcessing"]:
        shutil.rmtree(stale, ignore_errors=True)
    for log in folder.glob("log.*"):
        log.unlink()
    _run(case, ["blockMesh"], cores, False)
    if parallel:
        _run(case, ["decomposePar", "-force"], cores, False)
    _run(case, ["snappyHexMesh", "-overwrite"], cores, parallel)
    targets = sorted(folder.glob("processor*")) if parallel else [folder]
    for target in targets:
        shutil.copytree(folder / "0.orig", target / "0", dirs_exist_ok=True)
    cells = cell_count(folder)
    if cells <= 0:
        raise CaseError(f"snappyHexMesh left no cells; see {folder / 'log.snappyHexMesh'}")
    return cells


def solve(spec: CaseSpec, folder, cores: int = 1, resume: bool = False) -> None:
    """simpleFoam on a meshed case: first spec.start_iterations with first-order upwind for U
    (their log kept as log.simpleFoam.start), then on from there with the case's own schemes. With
    `resume` (an interrupted run wrote fields after its start) on from the latest of them, the log
    of the interrupted run kept as log.simpleFoam.<its latest write>."""
    from foamlib import FoamCase

    openfoam_environment()
    folder = Path(folder)
    case = FoamCase(folder)
    system = folder / "system"
    if resume:
        _write(system / "fvSchemes", _foam_entries(FV_SCHEMES))
        _write(system / "controlDict", _control(spec, restart=True))
        latest = _latest_time(folder)
        log = folder / "log.simpleFoam"
        if log.is_file():
            shutil.move(log, folder / f"log.simpleFoam.{latest:g}")
        # A stage that started at the latest write holds only rows the resumed run redoes, and
        # OpenFOAM would write beside its files instead of over them.
        for stage in (folder / "postProcessing").glob("*/*"):
            if re.fullmatch(r"\d+(\.\d+)?", stage.name) and float(stage.name) == latest:
                shutil.rmtree(stage)
        _run(case, ["simpleFoam"], cores, cores > 1)
        return
    shutil.rmtree(folder / "postProcessing", ignore_errors=True)  # a run interrupted before its first write
    if spec.start_iterations:
        _write(system / "fvSchemes", _foam_entries(FIRST_ORDER_SCHEMES))
        _write(system / "controlDict", _control(spec, end=spec.start_iterations))
        try:
            _run(case, ["simpleFoam"], cores, cores > 1)
        finally:
            _write(system / "fvSchemes", _foam_entries(FV_SCHEMES))
            _write(system / "controlDict", _control(spec, restart=True))
        shutil.move(folder / "log.simpleFoam", folder / "log.simpleFoam.start")
    _run(case, ["simpleFoam"], cores, cores > 1)


def stopped_early(spec: CaseSpec, result: Result) -> bool:
    """A case residual control stopped before its forces settled, and before its last iteration."""
    return result.convergence.status == "not converged" and result.convergence.iterations < spec.end_iteration - 1


def saved_result(folder) -> Result | None:
    """The result.json of a case folder, if it holds a readable one."""
    path = Path(folder) / "result.json"
    try:
        return Result.from_json(json.loads(path.read_text()))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def continue_case(spec: CaseSpec, folder, cores: int, previous: Result) -> Result:
    """Continue a case that stopped early (`stopped_early`) from its latest time, without residual
    control, to its level's last iteration; the verdict is taken again over the whole force
    history. The earlier solver log is kept as log.simpleFoam.<its last iteration>."""
    from foamlib import FoamCase

    openfoam_environment()
    folder = Path(folder)
    system = folder / "system"
    _write(system / "fvSolution", _foam_entries(FV_SOLUTION_TO_END))
    _write(system / "controlDict", _control(spec, restart=True))
    log = folder / "log.simpleFoam"
    if log.is_file():
        shutil.move(log, folder / f"log.simpleFoam.{previous.convergence.iterations}")
    start = time.monotonic()
    failure = None
    try:
        _run(FoamCase(folder), ["simpleFoam"], cores, cores > 1)
    except CaseError as exc:
        failure = str(exc)
    result = read_result(
        spec,
        folder,
        cells=previous.cells,
        cores=cores,
        mesh_seconds=previous.mesh_seconds,
        solve_seconds=previous.solve_seconds + time.monotonic() - start,
        failure=failure,
    )
    (folder / "result.json").write_text(json.dumps(result.to_json(), indent=1) + "\n")
    return result


def cell_count(folder) -> int:
    """Cells of the (possibly decomposed) mesh, from the owner files' headers."""
    folder = Path(folder)
    owners = sorted(folder.glob("processor*/constant/polyMesh/owner")) or [folder / "constant/polyMesh/owner"]
    total = 0
    for owner in owners:
        head = owner.read_bytes()[:2000].decode("latin-1")
        match = re.search(r"nCells:\s*(\d+)", head)
        total += int(match.group(1)) if match else 0
    return total


MESHED = "meshed.json"  # a case folder's mesh is complete: its cells, meshing time, solver start


def _meshed(spec: CaseSpec, folder: Path, cores: int) -> dict | None:
    """What meshed.json says of a folder meshed for this case on as many cores and not yet solved
    to the end (an interrupted run), or None: then the case is written and meshed afresh."""
    try:
        meshed = json.loads((folder / MESHED).read_text())
    except (OSError, ValueError):
        return None
    same = meshed.get("spec") == spec.case_id and meshed.get("cores") == cores and isinstance(meshed.get("cells"), int)
    return meshed if same else None


def _latest_time(folder: Path) -> float:
    """The latest time the solver wrote in a case folder (its first processor's, run in
    parallel); 0 when it wrote none."""
    base = folder / "processor0" if (folder / "processor0").is_dir() else folder
    times = [float(p.name) for p in base.glob("*") if p.is_dir() and re.fullmatch(r"\d+(\.\d+)?", p.name)]
    return max(times, default=0.0)


def _interrupted_seconds(folder: Path, meshed: dict) -> float:
    """Solver time an interrupted run already spent on the fields it wrote: from its start to its
    latest write (the work after that is redone, so not counted), plus what runs before it spent."""
    started = meshed.get("solve_started")
    if started is None:
        return 0.0
    base = folder / "processor0" if (folder / "processor0").is_dir() else folder
    latest = _latest_time(folder)
    written = [p.stat().st_mtime for p in base.glob("*") if p.is_dir() and p.name not in ("0", "constant")]
    kept = max(written, default=started) - started if latest > 0 else 0.0
    return float(meshed.get("solved_before", 0.0)) + max(kept, 0.0)


def run_case(spec: CaseSpec, folder, cores: int = 1) -> Result:
    """Write, mesh and solve one case; the Result (convergence verdict included) is also saved as
    result.json in the folder. A solver that stops with an error gives a diverged Result, not an
    exception; a case that cannot be meshed raises CaseError. A case stopped early
    (`stopped_early`) is continued, at once or, from a folder that holds one, when run again. A run
    interrupted (the folder meshed, no result.json) goes on from the fields it last wrote
    (CHECKPOINT_ITERATIONS), the mesh kept; before its first-order start was written, the solve
    starts over on the same mesh."""

    missing = openfoam_missing()
    if missing:
        raise CaseError(missing)
    folder = Path(folder)
    previous = saved_result(folder)
    if previous is not None and stopped_early(spec, previous):
        return continue_case(spec, folder, cores, previous)
    meshed = _meshed(spec, folder, cores) if previous is None else None
    if meshed is None:
        write_case(spec, folder, cores)
        start = time.monotonic()
        cells = mesh_case(folder, cores)
        meshed = {"spec": spec.case_id, "cells": cells, "cores": cores, "mesh_seconds": time.monotonic() - start}
        (folder / MESHED).write_text(json.dumps(meshed) + "\n")
    begun, failure = time.monotonic(), None
    resume = _latest_time(folder) >= max(spec.start_iterations, 1)
    earlier = _interrupted_seconds(folder, meshed) if resume else 0.0  # else every iteration is redone
    (folder / MESHED).write_text(json.dumps(meshed | {"solve_started": time.time(), "solved_before": earlier}) + "\n")
    try:
        solve(spec, folder, cores, resume=resume)
    except CaseError as exc:
        failure = str(exc)
    result = read_result(
        spec,
        folder,
        cells=meshed["cells"],
        cores=cores,
        mesh_seconds=meshed["mesh_seconds"],
        solve_seconds=earlier + time.monotonic() - begun,
        failure=failure,
    )
    (folder / "result.json").write_text(json.dumps(result.to_json(), indent=1) + "\n")
    if stopped_early(spec, result):
        return continue_case(spec, folder, cores, result)
    return result


# --- reading -----------------------------------------------------------------------------------


def read_table(path) -> np.ndarray:
    """A function object's .dat table as a float array (rows = iterations), parentheses dropped."""
    rows = []
    for line in Path(path).read_text().splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        values = line.replace("(", " ").replace(")", " ").split()
        try:
            rows.append([float(v) for v in values])
        except ValueError:
            continue
    width = max((len(r) for r in rows), default=0)
    return np.array([r for r in rows if len(r) == width], dtype=float).reshape(-1, width)


def force_history(folder, patch: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(iterations, total force (n, 3) [N], total moment about the CofR (n, 3) [N m]) of one
    patch, in the case frame and for the half (or quarter) of the body inside the domain."""
    base = Path(folder) / "postProcessing" / f"forces_{patch}"
    starts = _time_folders(base)
    if not starts:
        raise CaseError(f"no forces written for patch {patch} under {base}")
    # A case solved in stages (a first-order start, a resumed run) has one folder per stage, named
    # by its start; an interrupted stage's rows after the next one's start were redone by it.
    force, moment = (
        _stacked([read_table(start / name) for start in starts], starts) for name in ("force.dat", "moment.dat")
    )
    n = min(len(force), len(moment))
    return force[:n, 0], force[:n, 1:4], moment[:n, 1:4]


def _stacked(tables: list[np.ndarray], starts: list[Path]) -> np.ndarray:
    """The rows of several tables of one width (time first), in order, each up to the start of
    the next (its folder's name); empty ones skipped."""
    ends = [float(p.name) for p in starts[1:]] + [math.inf]
    tables = [t[t[:, 0] <= end] for t, end in zip(tables, ends, strict=True) if t.size]
    tables = [t for t in tables if t.size]
    return np.concatenate(tables) if tables else np.zeros((0, 10))


def _time_folders(base: Path) -> list[Path]:
    """A function object's output folders (one per solver start), in time order."""
    found = [p for p in Path(base).glob("*") if p.is_dir() and re.fullmatch(r"[\d.eE+-]+", p.name)]
    return sorted(found, key=lambda p: float(p.name))


def body_axes_history(spec: CaseSpec, body: Body, force: np.ndarray, moment: np.ndarray) -> np.ndarray:
    """(n, 3) whole-body X, Y [N] in the body's axes and N [N m] about its CB, from the forces on
    the part inside the domain: the half domain z >= 0 holds half of the body, so X, Y and N are
    doubled (Z, K, M cancel with the mirror half and are not used); the quarter domain (zero
    drift, y >= 0 as well) holds a quarter, so X is multiplied by 4 and Y, N are zero by
    symmetry."""
    e_x, e_y = body.axes
    x = force @ e_x
    y = force @ e_y
    n = moment[:, 2]
    if spec.quarter:
        return np.column_stack([4.0 * x, 0.0 * x, 0.0 * x])
    return np.column_stack([2.0 * x, 2.0 * y, 2.0 * n])


def coefficient_scale(spec: CaseSpec, body: Body) -> np.ndarray:
    """Divisors of X, Y, N: (1/2) rho U^2 L^2, L^2, L^3 with the body's length (thesis section
    5.2; docs/hydro/README.md, "Conventions")."""
    q = 0.5 * spec.rho * spec.speed**2
    return np.array([q * body.length**2, q * body.length**2, q * body.length**3])


def final_residuals(log) -> dict[str, float]:
    """The initial residual of each equation at the last iteration of a simpleFoam log."""
    out: dict[str, float] = {}
    try:
        text = Path(log).read_text(errors="replace")
    except OSError:
        return out
    last = text.rsplit("\nTime = ", 1)[-1]
    for name, value in re.findall(r"Solving for (\w+), Initial residual = ([\d.eE+-]+)", last):
        out.setdefault(name, float(value))
    return out


def converged_by_residuals(log) -> bool:
    try:
        return "SIMPLE solution converged" in Path(log).read_text(errors="replace")
    except OSError:
        return False


def layers_added(log, patch: str) -> float | None:
    """The mean number of boundary layers snappyHexMesh added on a patch (its last summary)."""
    try:
        text = Path(log).read_text(errors="replace")
    except OSError:
        return None
    found = re.findall(rf"^{re.escape(patch)}\s+\d+\s+([\d.eE+-]+)\s", text, flags=re.M)
    return float(found[-1]) if found else None


def spread_window(iterations: int) -> int:
    """The last iterations a case's value and spread are taken over (SPREAD_WINDOW of them)."""
    return max(1, int(round(SPREAD_WINDOW * iterations)))


def _named(values) -> dict[str, float]:
    return dict(zip(("X", "Y", "N"), map(float, values), strict=True))


def verdict(
    coefficients: np.ndarray, residuals: dict[str, float], failure: str | None = None, quarter: bool = False
) -> tuple[Convergence, np.ndarray]:
    """The convergence verdict of a coefficient history (n, 3) and the mean over the last
    SPREAD_WINDOW of the iterations:
    - diverged: the solver stopped with an error, or a coefficient is not finite or beyond
      DIVERGED_COEFFICIENT;
    - not converged: a coefficient's spread over the window exceeds SPREAD_RELATIVE of its mean
      (or SPREAD_ABSOLUTE, whichever is larger);
    - converged otherwise."""
    n = len(coefficients)
    window = spread_window(n)
    tail = coefficients[-window:] if n else np.full((1, 3), np.nan)
    mean = tail.mean(axis=0)
    spread = tail.max(axis=0) - tail.min(axis=0)
    names = ("X", "Y", "N")
    spreads = _named(spread)

    def make(status, reason):
        return Convergence(status, reason, n, window, spreads, residuals), mean

    if failure:
        return make("diverged", failure)
    if n == 0 or not np.all(np.isfinite(coefficients)):
        return make("diverged", "the forces are not finite")
    worst = np.max(np.abs(coefficients[-1]))
    if worst > DIVERGED_COEFFICIENT:
        return make("diverged", f"a coefficient reached {worst:.3g} (a flow round a hull gives about 1e-3)")
    limits = np.maximum(SPREAD_RELATIVE * np.abs(mean), SPREAD_ABSOLUTE)
    checked = (0,) if quarter else (0, 1, 2)
    over = [i for i in checked if spread[i] > limits[i]]
    if over:
        text = ", ".join(f"{names[i]}' spreads {spread[i]:.2e} (limit {limits[i]:.2e})" for i in over)
        return make("not converged", f"over the last {window} of {n} iterations {text}")
    return make(
        "converged",
        f"spread within {SPREAD_RELATIVE:.0%} (or {SPREAD_ABSOLUTE:g}) over the last {window} of {n} iterations",
    )


def read_y_plus(folder) -> dict[str, dict[str, float]]:
    """min / max / mean y+ per wall patch at the last write, from the yPlus function object."""
    out: dict[str, dict[str, float]] = {}
    for path in (start / "yPlus.dat" for start in _time_folders(Path(folder) / "postProcessing" / "yPlus")):
        if not path.is_file():
            continue
        for line in path.read_text().splitlines():
            parts = line.split()
            if len(parts) == 5 and not line.startswith("#"):
                try:
                    out[parts[1]] = {"min": float(parts[2]), "max": float(parts[3]), "mean": float(parts[4])}
                except ValueError:
                    continue
    return out


def openfoam_version() -> str:
    try:
        header = Path(OPENFOAM_DIR, "etc", "controlDict").read_text(errors="replace")[:2000]
    except OSError:
        return ""
    match = re.search(r"Version:\s*(\S+)", header)
    return f"OpenFOAM {match.group(1)}" if match else "OpenFOAM"


def read_result(
    spec: CaseSpec,
    folder,
    *,
    cells: int,
    cores: int,
    mesh_seconds: float,
    solve_seconds: float,
    failure: str | None = None,
) -> Result:
    """The Result of a solved case folder: forces, coefficients and the convergence verdict."""
    folder = Path(folder)
    residuals = final_residuals(folder / "log.simpleFoam")
    histories = {}
    for body in spec.bodies:
        try:
            _, force, moment = force_history(folder, body.patch)
        except (CaseError, OSError):
            force = moment = np.zeros((0, 3))
        histories[body.patch] = body_axes_history(spec, body, force, moment)
    measured = histories.pop(spec.body.patch)
    scale = coefficient_scale(spec, spec.body)
    convergence, mean = verdict(measured / scale, residuals, failure, spec.quarter)
    layers = layers_added(folder / "log.snappyHexMesh", spec.body.patch)
    wanted = boundary_layers(spec)[0]
    if convergence.status != "diverged" and layers is not None and layers < MIN_LAYER_SHARE * wanted:
        convergence.status = "bad mesh"
        convergence.reason = f"snappyHexMesh added {layers:.2g} of {wanted} boundary layers on {spec.body.patch}"
    forces = {spec.body.patch: _named(mean * scale)}
    forces |= {patch: _named(h[-spread_window(len(h)) :].mean(axis=0)) for patch, h in histories.items() if len(h)}
    return Result(
        case_id=spec.case_id,
        kind=spec.kind,
        level=spec.level,
        wall_function=spec.wall_function,
        y_plus_target=spec.y_plus,
        cells=int(cells),
        cores=int(cores),
        mesh_seconds=float(mesh_seconds),
        solve_seconds=float(solve_seconds),
        coefficients=_named(mean),
        forces=forces,
        convergence=convergence,
        y_plus=read_y_plus(folder),
        inputs=spec.inputs,
        openfoam=openfoam_version(),
        turbulence=spec.turbulence,
        inflow_intensity=spec.inflow_intensity,
        inflow_viscosity_ratio=spec.inflow_viscosity_ratio,
    )
