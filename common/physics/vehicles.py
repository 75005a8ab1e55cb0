"""Vehicle library: mass properties and the coefficients of thesis (5.10)/(5.11).

Every number cites its source; docs/design.md, "Vehicle data and sources", lists them with the
unit conversions and the reasons for each choice:
- [PRE]    Prestero (2001), "Verification of a six-degree of freedom simulation model for the
           REMUS autonomous underwater vehicle", MIT/WHOI MS thesis, appendix tables (REMUS 100).
- [NPSNET] the NPSNET-IV simulator's `SUBmodel.h` / `UUVbody.cc` (NPS AUV II "Phoenix", the data
           of Healey & Lienard 1993, IEEE J. Oceanic Eng. 18(3), with Bahrke 1992, Warner 1991,
           Marco 1995).
- [MSS-old]/[MSS] Fossen's MSS toolbox `npsauv.m` (the older file by Lauvdal 1994 and the current
           one: the 5.3 m SDV data set of Healey & Lienard 1993, after Smith, Crane & Summey 1978).

Sign convention (Prestero 2001 / Healey & Lienard 1993): Y_uudr > 0 and N_uudr < 0, so a positive
rudder angle gives a negative yaw rate. Units are SI; angles in radians.
"""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field, model_validator


class Gains(BaseModel):
    """PID gains of one loop (thesis (5.21)); `integral_limit` clips the integral state."""

    model_config = ConfigDict(extra="forbid")

    kp: float
    ki: float = 0.0
    kd: float = 0.0
    integral_limit: float = Field(default=math.inf, gt=0)


class PidTuning(BaseModel):
    """Heading loop (error in rad -> rudder in rad) and speed loop (error in m/s -> newtons)."""

    model_config = ConfigDict(extra="forbid")

    heading: Gains
    speed: Gains


class Vehicle(BaseModel):
    """A UUV for the 3-DOF horizontal-plane model (5.10). Origin at the centre of buoyancy,
    x_G = y_G = 0 (as in Prestero 2001 and Healey & Lienard 1993), so no m x_G terms appear."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    length: float = Field(gt=0, description="L_uuv [m]")
    diameter: float = Field(gt=0, description="D_uuv [m]")
    mass: float = Field(gt=0, description="m [kg]")
    Izz: float = Field(gt=0, description="yaw moment of inertia [kg m^2]")
    rho: float = Field(gt=0, description="water density the coefficients were made with [kg/m^3]")
    # Added mass (5.10)
    X_udot: float
    Y_vdot: float
    Y_rdot: float
    N_vdot: float
    N_rdot: float
    # Forces and moments (5.11)
    X_uu: float = Field(le=0, description="X_u|u| [kg/m]")
    X_vr: float
    X_rr: float
    Y_vv: float = Field(description="Y_v|v| [kg/m]")
    Y_rr: float = Field(description="Y_r|r| [kg m/rad^2]")
    Y_uv: float
    Y_ur: float
    Y_uudr: float
    N_vv: float = Field(description="N_v|v| [kg]")
    N_rr: float = Field(description="N_r|r| [kg m^2/rad^2]")
    N_uv: float
    N_ur: float
    N_uudr: float
    N_uv_compensation: float | None = Field(
        default=None, description="N_uv for N_uv compensation (6.1) where the data set's N_uv is 0"
    )
    thesis_M11: float | None = Field(default=None, description="M11 the thesis quotes (section 6.3.1), for gamma (6.4)")
    # Actuator limits
    max_rudder: float = Field(gt=0, le=math.pi / 2, description="rudder limit [rad]")
    max_thrust: float = Field(gt=0, description="propeller thrust limit [N]")
    pid: PidTuning

    @model_validator(mode="after")
    def _mass_matrix_invertible(self) -> Vehicle:
        m22 = self.mass - self.Y_vdot
        m33 = self.Izz - self.N_rdot
        det = m22 * m33 - self.Y_rdot * self.N_vdot
        if self.mass - self.X_udot <= 0 or det <= 0:
            raise ValueError(
                f"mass matrix of vehicle '{self.name}' is not positive definite "
                f"(M11 = {self.mass - self.X_udot:.4g}, det(M22..M33) = {det:.4g})"
            )
        return self

    @property
    def M11(self) -> float:
        """Surge inertia m - X_udot (thesis section 6.3.1 quotes it per vehicle)."""
        return self.mass - self.X_udot

    @property
    def compensation_N_uv(self) -> float:
        return self.N_uv_compensation if self.N_uv_compensation is not None else self.N_uv


_DEG = math.pi / 180.0

# --- Small: REMUS 100, Prestero (2001) appendix tables [PRE] ---------------------------------
REMUS100 = Vehicle(
    name="remus100",
    length=1.33,  # [PRE] L = 1.33 m
    diameter=0.191,  # [PRE] d = 0.191 m
    mass=30.48,  # [PRE] m = W/g = 299 N / 9.81
    Izz=3.45,  # [PRE] Izz
    rho=1025.0,  # [PRE] sea water
    X_udot=-0.93,  # [PRE] table C.5
    Y_vdot=-35.5,  # [PRE]
    Y_rdot=1.93,  # [PRE]
    N_vdot=1.93,  # [PRE]
    N_rdot=-4.88,  # [PRE]
    X_uu=-1.62,  # [PRE] axial drag
    X_vr=35.5,  # [PRE] table C.6 (= -Y_vdot)
    X_rr=-1.93,  # [PRE] (= -Y_rdot)
    Y_vv=-1310.0,  # [PRE] table C.2 as printed; reproduces the thesis -10.04 deg/s (docs/design.md)
    Y_rr=0.632,  # [PRE]
    Y_uv=-28.6,  # [PRE] body + fin lift
    Y_ur=5.22,  # [PRE] Y_ura + Y_urf = -0.93 + 6.15
    Y_uudr=9.64,  # [PRE] table C.10
    N_vv=-3.18,  # [PRE]
    N_rr=-94.0,  # [PRE]
    N_uv=-24.0,  # [PRE] N_uva + N_uvb + N_uvf
    N_ur=-2.00,  # [PRE] 1.93 - 3.93
    N_uudr=-6.15,  # [PRE]
    thesis_M11=33.6,  # thesis section 6.3.1 (Prestero's numbers give 31.41 kg; docs/physics.md)
    max_rudder=15.0 * _DEG,  # Fossen's PythonVehicleSimulator remus100.py deltaMax_r
    max_thrust=10.0,  # nearsub's estimate: -X_u|u| * 2.5^2, Fossen's remus100 top speed 2.5 m/s
    pid=PidTuning(
        # docs/pid-tuning.md: positional form, designed at 1.5 m/s (rudder saturates beyond 10 deg
        # of heading error, slowest PD poles at damping 0.9, Ki = Kp w/10; surge pole 3x drag pole).
        heading=Gains(kp=1.5, ki=0.13, kd=3.4, integral_limit=0.1),
        speed=Gains(kp=9.7, ki=0.45, kd=0.0, integral_limit=5.0),
    ),
)

# --- Medium: NPS AUV II, NPSNET-IV SUBmodel.h British-unit block [NPSNET] (rho = 1000) ------
_NPS_L = 2.2256  # [NPSNET] 7.302 ft
_NPS_Q2 = 0.5 * 1000.0 * _NPS_L**2  # rho/2 L^2 = 2476.7
_NPS_Q3 = _NPS_Q2 * _NPS_L  # rho/2 L^3 (5512.4)
_NPS_Q4 = _NPS_Q3 * _NPS_L  # rho/2 L^4 (12268)
_NPS_Q5 = _NPS_Q4 * _NPS_L  # rho/2 L^5 (27305)
NPS_AUV_II = Vehicle(
    name="nps_auv_ii",
    length=_NPS_L,
    diameter=0.419,  # [NPSNET] max breadth 16.5 in (hull is not circular; height 0.257 m)
    mass=197.31,  # [NPSNET] W = 435 lb
    Izz=61.01,  # [NPSNET] Iz = 45 slug ft^2
    rho=1000.0,  # Healey's nondimensional sets use fresh water (docs/design.md)
    X_udot=-2.82e-3 * _NPS_Q3,  # [NPSNET] X'_udot
    Y_vdot=-3.43e-2 * _NPS_Q3,  # [NPSNET]
    Y_rdot=-1.78e-3 * _NPS_Q4,  # [NPSNET]
    N_vdot=-1.78e-3 * _NPS_Q4,  # [NPSNET]
    N_rdot=-4.7e-4 * _NPS_Q5,  # [NPSNET]
    X_uu=-0.00778 * _NPS_Q2,  # [NPSNET] -(rho/2) L^2 C_d0, C_d0 = 0.00778
    X_vr=0.0,  # not in Bahrke's (1992) model [NPSNET]
    X_rr=0.0,  # not in Bahrke's (1992) model [NPSNET]
    Y_vv=-122.7,  # strip cross-flow, C_dy = 0.5 over the heights hh(x) of [NPSNET] UUVbody.cc
    Y_rr=-6.47,  # same strip integral
    Y_uv=-1.07e-1 * _NPS_Q2,  # [NPSNET] Y'_v
    Y_ur=0.0,  # [NPSNET] (Warner 1991 gives +1.187e-2; not used)
    Y_uudr=0.0,  # [NPSNET] bow and stern rudders (+1.18e-2 each) deflect in opposite senses: net 0
    N_vv=-6.82,  # same strip integral
    N_rr=-31.8,  # same strip integral
    N_uv=0.0,  # [NPSNET] (Marco 1995 gives -7.69e-3; not used in the dynamics)
    N_ur=-3.90e-3 * _NPS_Q4,  # [NPSNET] N'_r
    N_uudr=-7.79e-3 * _NPS_Q3,  # [NPSNET] -(0.283+0.377)*1.18e-2, consistent form (docs/design.md)
    N_uv_compensation=-7.69e-3 * _NPS_Q3,  # Marco's (1995) N'_v = -7.69e-3: N_uv is 0 here
    thesis_M11=212.9,  # thesis section 6.3.1
    max_rudder=15.0 * _DEG,  # the thesis's section 5.10 manoeuvre uses +/-15 deg
    max_thrust=4.0 * 0.00778 * _NPS_Q2,  # assumption: X_prop for 2 m/s (= -X_u|u| * 2^2)
    pid=PidTuning(
        # docs/pid-tuning.md: same method, designed at 1.0 m/s.
        heading=Gains(kp=1.5, ki=0.073, kd=2.2, integral_limit=0.1),
        speed=Gains(kp=77.0, ki=4.2, kd=0.0, integral_limit=38.0),
    ),
)

# --- Large: SDV, the older MSS npsauv.m [MSS-old] (rho = 1000) -------------------------------
_SDV_L = 5.3  # [MSS-old]
_SDV_Q2 = 0.5 * 1000.0 * _SDV_L**2  # rho/2 L^2 = 14045
_SDV_Q3 = _SDV_Q2 * _SDV_L  # 74438
_SDV_Q4 = _SDV_Q3 * _SDV_L  # 394522
_SDV_Q5 = _SDV_Q4 * _SDV_L  # 2.0910e6
SDV = Vehicle(
    name="sdv",
    length=_SDV_L,
    diameter=0.53,  # [MSS] cross-flow height H = 0.53 m
    mass=5454.54,  # [MSS-old] m = 5454.54/(rho/2 L^3) in prime units
    Izz=13587.0,  # [MSS]
    rho=1000.0,  # [MSS-old]
    X_udot=-7.6e-3 * _SDV_Q3,  # [MSS-old]
    Y_vdot=-5.5e-2 * _SDV_Q3,  # [MSS-old]
    Y_rdot=1.2e-3 * _SDV_Q4,  # [MSS-old]
    N_vdot=1.2e-3 * _SDV_Q4,  # [MSS-old]
    N_rdot=-3.4e-3 * _SDV_Q5,  # [MSS-old]
    X_uu=-0.00385 * _SDV_Q2,  # [MSS] propulsion model C_d0 = 0.00385
    X_vr=2.0e-2 * _SDV_Q3,  # [MSS-old]
    X_rr=4.0e-3 * _SDV_Q4,  # [MSS-old]
    Y_vv=-702.3,  # cross-flow, C_dy = 0.5, H = 0.53 m over [-L/2, L/2] ([MSS])
    Y_rr=0.0,  # 0 by symmetry of the [-L/2, L/2] integral
    Y_uv=-1.0e-1 * _SDV_Q2,  # [MSS-old] Y'_v
    Y_ur=3.0e-2 * _SDV_Q3,  # [MSS-old] Y'_r
    Y_uudr=2.7e-2 * _SDV_Q2,  # [MSS-old] Y'_dr
    N_vv=0.0,  # 0 by symmetry of the [-L/2, L/2] integral
    N_rr=-3267.0,  # -rho/2 C_dy H L^4/32 ([MSS] cross-flow)
    N_uv=-7.4e-3 * _SDV_Q3,  # [MSS-old] N'_v
    N_ur=-1.6e-2 * _SDV_Q4,  # [MSS-old] N'_r
    N_uudr=-1.3e-2 * _SDV_Q3,  # [MSS-old] N'_dr
    thesis_M11=6020.0,  # thesis section 6.3.1
    max_rudder=20.0 * _DEG,  # [MSS] max_u
    max_thrust=192.0,  # [MSS] SIMnpsauv.m Xprop model at 1500 rpm
    pid=PidTuning(
        # docs/pid-tuning.md: same method, designed at 1.5 m/s.
        heading=Gains(kp=2.0, ki=0.049, kd=6.2, integral_limit=0.1),
        speed=Gains(kp=324.0, ki=2.6, kd=0.0, integral_limit=96.0),
    ),
)

LIBRARY: dict[str, Vehicle] = {v.name: v for v in (REMUS100, NPS_AUV_II, SDV)}
ALIASES = {"small": "remus100", "medium": "nps_auv_ii", "large": "sdv", "remus": "remus100"}


def get_vehicle(name: str) -> Vehicle:
    """Look up a library vehicle by name or size alias (small / medium / large)."""
    key = ALIASES.get(name.lower(), name.lower())
    try:
        return LIBRARY[key]
    except KeyError:
        known = ", ".join(sorted(LIBRARY) + sorted(ALIASES))
        raise KeyError(f"unknown vehicle {name!r}; known: {known}") from None
