"""Helm behaviours as pure functions of the state and their parameters.

`waypoints` follows thesis section 5.7 with MOOS-IvP BHV_Waypoint semantics (the MOOS-IvP helm
documentation, Benjamin et al.): the vehicle steers at a lead point `lead` metres ahead of its perpendicular foot on
the track-line from the previous waypoint; the lead point never passes the next waypoint. A
waypoint counts as reached when the vehicle is within `capture_radius`, or it has started to
move away after coming within `slip_radius` (slip), or, with `capture_line`, it has crossed the
line through the waypoint perpendicular to the track (capture line).

The geometry helpers work element-wise on arrays so that batch sweeps reuse them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from nearsub.common.autonomy import control
from nearsub.common.physics import dynamics, proximity
from nearsub.common.physics.hull import uuv_body_outline
from nearsub.common.physics.vehicles import Vehicle

# Positions in a mission lie within this range of the submarine [m]: a nearsub choice that turns
# a slip of the exponent (1e12) into an error; the largest envelope reaches about 1.5 L_sub.
MAX_RANGE = 100_000.0
MAX_SPEED = 20.0  # [m/s]: beyond any UUV or submarine of the vehicle library (nearsub choice)
Coordinate = Annotated[float, Field(ge=-MAX_RANGE, le=MAX_RANGE)]
Speed = Annotated[float, Field(ge=-MAX_SPEED, le=MAX_SPEED)]


class Leg(BaseModel):
    """One BHV_Waypoint block: a list of points visited in order at one speed."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    name: str = "leg"
    points: list[tuple[Coordinate, Coordinate]] = Field(min_length=1)
    speed: float = Field(gt=0, le=MAX_SPEED, description="desired speed through the water [m/s]")
    lead: float | None = Field(default=None, gt=0, description="d_lead [m]; None steers at the waypoint")
    lead_damper: float | None = Field(default=None, gt=0)
    capture_radius: float = Field(default=3.0, gt=0)
    slip_radius: float | None = Field(default=None, gt=0)
    capture_line: bool = False
    lead_to_start: bool = False


def track_geometry(prev_xy: np.ndarray, next_xy: np.ndarray, pos_xy: np.ndarray):
    """Unit track direction, track length, along-track position of the vehicle's perpendicular
    foot, and signed cross-track offset (left of the track positive)."""
    track = next_xy - prev_xy
    length = np.hypot(track[..., 0], track[..., 1])
    safe = np.where(length > 0, length, 1.0)
    ux, uy = track[..., 0] / safe, track[..., 1] / safe
    rel = pos_xy - prev_xy
    along = rel[..., 0] * ux + rel[..., 1] * uy
    cross = ux * rel[..., 1] - uy * rel[..., 0]
    return np.stack([ux, uy], axis=-1), length, along, cross


def lead_point(prev_xy, next_xy, pos_xy, lead, lead_damper=None):
    """The point the vehicle steers at (thesis figure 5-4): `lead` ahead of the perpendicular foot,
    clamped at the next waypoint. Near the track (within lead_damper) MOOS lengthens the lead by
    1 + 2 (1 - d / lead_damper) to damp the approach."""
    direction, length, along, cross = track_geometry(prev_xy, next_xy, pos_xy)
    effective = np.asarray(lead, dtype=float)
    if lead_damper is not None:
        d = np.abs(cross)
        effective = np.where(d < lead_damper, effective * (1.0 + 2.0 * (1.0 - d / lead_damper)), effective)
    s = np.minimum(along + effective, length)
    point = prev_xy + direction * s[..., None]
    return np.where((length > 0)[..., None], point, next_xy)


def crossed_capture_line(prev_xy, next_xy, pos_xy):
    """True once the vehicle is past the line through the waypoint perpendicular to the track
    (the angle at the waypoint between the previous waypoint and the vehicle is >= 90 deg)."""
    a = prev_xy - next_xy
    b = pos_xy - next_xy
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] <= 0.0


@dataclass(frozen=True)
class WaypointProgress:
    """Where the behaviour is; JSON-able so a swapped-in helm can resume it."""

    leg: int = 0
    index: int = 0
    previous: tuple[float, float] | None = None
    closest: float = math.inf
    reached: int = 0
    complete: bool = False

    def to_dict(self) -> dict:
        return {
            "leg": self.leg,
            "index": self.index,
            "previous": list(self.previous) if self.previous is not None else None,
            "closest": None if math.isinf(self.closest) else self.closest,
            "reached": self.reached,
            "complete": self.complete,
        }

    @classmethod
    def from_dict(cls, data: dict) -> WaypointProgress:
        prev = data.get("previous")
        closest = data.get("closest")
        return cls(
            leg=int(data["leg"]),
            index=int(data["index"]),
            previous=tuple(prev) if prev is not None else None,
            closest=math.inf if closest is None else float(closest),
            reached=int(data["reached"]),
            complete=bool(data["complete"]),
        )


@dataclass(frozen=True)
class HelmDecision:
    u_d: float
    psi_d: float
    progress: WaypointProgress
    target: tuple[float, float] | None
    captured: tuple[tuple[int, int, tuple[float, float]], ...] = ()


def initial_progress(legs: list[Leg], start_xy: tuple[float, float]) -> WaypointProgress:
    """Start on the first point; with lead_to_start the first track-line begins at the start."""
    previous = start_xy if legs[0].lead_to_start else None
    return WaypointProgress(previous=previous)


def _arrived(leg: Leg, progress: WaypointProgress, target: np.ndarray, pos: np.ndarray, dist: float) -> bool:
    if dist < leg.capture_radius:
        return True
    if leg.slip_radius is not None and dist > progress.closest and progress.closest <= leg.slip_radius:
        return True
    if leg.capture_line and progress.previous is not None:
        return bool(crossed_capture_line(np.asarray(progress.previous), target, pos))
    return False


@dataclass(frozen=True)
class CrossFlow:
    """What the modified waypoints behaviour needs to know: the submarine's speed through the
    water (the cross-flow in the submarine frame), alpha of (6.2) and the UUV's length."""

    u_sub: float
    alpha: float
    uuv_length: float


def waypoints(
    legs: list[Leg], progress: WaypointProgress, x: float, y: float, psi: float, cross_flow: CrossFlow | None = None
) -> HelmDecision:
    """The waypoints behaviour: advance past reached waypoints, then steer at the lead point of
    the current track-line. Standard (section 5.7): the lead point lies on the track-line and the
    speed is the leg's. Modified (section 6.3.2, when `cross_flow` is given): the lead point and
    the speed come from (6.2) and (6.3), with U_ot = leg speed - U_sub."""
    pos = np.array([x, y])
    captured = []
    while not progress.complete:
        leg = legs[progress.leg]
        target = np.asarray(leg.points[progress.index], dtype=float)
        dist = float(np.hypot(*(target - pos)))
        if not _arrived(leg, progress, target, pos, dist):
            progress = replace(progress, closest=min(progress.closest, dist))
            break
        captured.append((progress.leg, progress.index, (float(target[0]), float(target[1]))))
        index, leg_index = progress.index + 1, progress.leg
        if index == len(leg.points):
            index, leg_index = 0, leg_index + 1
        progress = replace(
            progress,
            leg=min(leg_index, len(legs) - 1),
            index=index if leg_index < len(legs) else progress.index,
            previous=(float(target[0]), float(target[1])),
            closest=math.inf,
            reached=progress.reached + 1,
            complete=leg_index >= len(legs),
        )
    if progress.complete:
        return HelmDecision(0.0, psi, progress, None, tuple(captured))
    leg = legs[progress.leg]
    target = np.asarray(leg.points[progress.index], dtype=float)
    if leg.lead is None or progress.previous is None:  # no track-line yet: head for the waypoint
        speed, psi_d = leg.speed, np.arctan2(target[1] - y, target[0] - x)
    else:
        previous = np.asarray(progress.previous)
        speed, psi_d = steer(previous, target, pos, leg.speed, leg.lead, leg.lead_damper, cross_flow)
    return HelmDecision(float(speed), float(psi_d), progress, (float(target[0]), float(target[1])), tuple(captured))


def steer(prev_xy, next_xy, pos_xy, speed, lead, lead_damper=None, cross_flow: CrossFlow | None = None):
    """Desired speed and heading on one track-line, element-wise over vehicles (the helm calls it
    for one, the batch engine for many): at the lead point of section 5.7, or with `cross_flow` at
    the modified lead point (6.2) with the speed policy (6.3), U_ot = speed - U_sub."""
    if cross_flow is None:
        aim = lead_point(prev_xy, next_xy, pos_xy, lead, lead_damper)
    else:
        u_ot = speed - cross_flow.u_sub
        aim = modified_lead_point(prev_xy, next_xy, pos_xy, lead, u_ot, cross_flow.u_sub, cross_flow.alpha)
        speed = speed_policy(prev_xy, next_xy, pos_xy, cross_flow.u_sub, u_ot, cross_flow.uuv_length)
    psi_d = np.arctan2(aim[..., 1] - pos_xy[..., 1], aim[..., 0] - pos_xy[..., 0])
    return speed, psi_d


# --- Modified waypoints (thesis section 6.3.2) ------------------------------------------------
def modified_lead_point(prev_xy, next_xy, pos_xy, d_lead, u_ot, u_sub, alpha):
    """Lead point of the modified waypoints behaviour (thesis figure 6-4): from the perpendicular
    foot on the track-line, move d_lead along U_sub (+x) and d_off (6.2) across it, towards the
    next waypoint: d_off = alpha d_lead U_ot sin(beta) / U_sub, beta the angle from U_sub to the
    track-line. The UUV then points mostly into the cross-flow and crabs along the track."""
    direction, _, along, _ = track_geometry(prev_xy, next_xy, pos_xy)
    foot = prev_xy + direction * along[..., None]
    sin_beta = direction[..., 1]  # U_sub is along +x, so sin(beta) is the track's y component
    d_off = alpha * d_lead * u_ot * sin_beta / u_sub  # (6.2)
    return np.stack([foot[..., 0] + d_lead, foot[..., 1] + d_off], axis=-1)


def speed_policy(prev_xy, next_xy, pos_xy, u_sub, u_ot, uuv_length):
    """Desired speed (6.3): U_UUV = U_sub + U_ot cos(beta) + epsilon.

    The curve of figure 6-5 chosen here: epsilon = |U_ot| * sat(d_lag / L_uuv), with d_lag the
    distance by which the UUV lags its perpendicular foot on the track-line in the direction of
    U_sub (+x), and sat the unit saturation. So epsilon is proportional to the lag and saturates
    at +/-|U_ot| when the UUV lags (or leads) by one UUV length, as section 6.3.2 describes.
    """
    direction, _, along, _ = track_geometry(prev_xy, next_xy, pos_xy)
    foot_x = prev_xy[..., 0] + direction[..., 0] * along
    lag = foot_x - pos_xy[..., 0]
    epsilon = np.abs(u_ot) * np.clip(lag / uuv_length, -1.0, 1.0)
    return u_sub + u_ot * direction[..., 0] + epsilon  # cos(beta) = the track's x component


# --- N_uv compensation (thesis section 6.3.1) ------------------------------------------------
def gamma_from_m11(m11):
    """gamma(M11) = 10^(4.538 log10(M11)^-4.364), thesis (6.4)."""
    return 10.0 ** (4.538 * np.log10(m11) ** -4.364)


def nuv_heading_offset(n_s, u_d, n_uv, gamma):
    """Delta psi of (6.1) as corrected (docs/design.md, "Thesis errata"): v_comp = gamma N_s / (N_uv u_d) and
    Delta psi = atan2(v_comp, u_d). Flying at psi_d + Delta psi while the course stays on psi_d
    gives the sway v = -u sin(Delta psi), whose Munk moment N_uv u v then opposes N_s."""
    v_comp = gamma * n_s / (n_uv * u_d)
    return np.arctan2(v_comp, u_d)


# --- Tip-clearance guard on the N_uv offset (nearsub; docs/design.md, "Physics decisions") -------
# Candidate offsets between 0 and (6.1)'s command at which the tips' clearance is checked; the limit
# is then placed by linear interpolation between the last safe and the first unsafe one. 24 steps
# of a 20 deg offset are 0.8 deg apart: nearsub's choice, a small fraction of the offsets (6.1) asks.
GUARD_SAMPLES = 24
# An offset also sets the course, and a cut offset takes effect only as fast as the heading loop
# turns the UUV back: the guard checks each candidate's course for the vehicle's course lag
# (`course_lag`), at its start, middle and end. The hull outline is convex, so along a straight
# course the clearance is convex in time and can dip between samples only where the course passes
# the hull's nearest point.
GUARD_COURSE_POINTS = 3
# The course lag is measured on a LAG_STEP heading step (a typical (6.1) offset) from straight flight
# in still water, at the speed rounded to LAG_SPEED_RESOLUTION, with the positional PID at the alpha
# mission's step LAG_DT, over LAG_DURATION (the SDV's lag peaks 12-16 s after the step): nearsub's
# choices.
LAG_STEP = math.radians(10.0)
LAG_SPEED_RESOLUTION = 0.1  # [m/s]
LAG_DT = 0.05  # [s]
LAG_DURATION = 60.0  # [s]


@dataclass(frozen=True)
class GuardedOffset:
    """The guard's answer, element-wise over vehicles: the offset to fly [rad], the limit the tip
    clearance puts on it [rad] (signed as the command; +/-inf where there is none), whether that
    limit lies within the command (active) and whether the limit or the rate limit cut the command
    (saturated)."""

    delta_psi: np.ndarray
    limit: np.ndarray
    active: np.ndarray
    saturated: np.ndarray


def tip_clearance(x, y, psi, length: float, diameter: float):
    """Signed clearance [m] of the UUV's tips (bow and stern points of its outline, `hull`) from the
    submarine's outline, the smaller of the two (`proximity.hull_signed_distance`)."""
    bow, stern = _tips(length, diameter)
    x, y, psi = (np.asarray(a, dtype=float) for a in (x, y, psi))
    cos_psi, sin_psi = np.cos(psi), np.sin(psi)
    return np.minimum(
        proximity.hull_signed_distance(x + bow * cos_psi, y + bow * sin_psi),
        proximity.hull_signed_distance(x + stern * cos_psi, y + stern * sin_psi),
    )


@lru_cache(maxsize=16)
def _tips(length: float, diameter: float) -> tuple[float, float]:
    bx, _ = uuv_body_outline(length, diameter)
    return float(bx.max()), float(bx.min())


def course_lag(vehicle: Vehicle, speed) -> np.ndarray:
    """How long [s] the vehicle keeps flying its old course after its heading command changes: the
    largest distance by which its path lags the new course, over speed sin(step), for a LAG_STEP
    step of its own heading loop (`control.pid_step`, (5.10) through `dynamics.step`). Element-wise
    over speeds [m/s]; 1.9 s for the REMUS 100, 2.2 s for the NPS AUV II and 6.3 s for the SDV at
    1.5 m/s."""
    speed = np.asarray(speed, dtype=float)
    quantised = np.maximum(np.round(speed / LAG_SPEED_RESOLUTION), 1.0) * LAG_SPEED_RESOLUTION
    key = vehicle.model_dump_json()  # a Vehicle is not hashable (its PID tuning is mutable)
    if quantised.ndim == 0:  # one vehicle's speed (the helm's every step): no np.vectorize
        return np.array(_course_lag(key, float(quantised)))
    lags = {u: _course_lag(key, u) for u in np.unique(quantised).tolist()}
    return np.vectorize(lags.__getitem__, otypes=[float])(quantised)


@lru_cache(maxsize=64)
def _course_lag(vehicle_json: str, speed: float) -> float:
    vehicle = Vehicle.model_validate_json(vehicle_json)
    state = np.array([speed, 0.0, 0.0, 0.0, 0.0, 0.0])
    memory = replace(control.PidState.zeros(), thrust=np.asarray(-vehicle.X_uu * speed * speed))
    still = dynamics.Environment()
    worst = 0.0
    for _ in range(int(round(LAG_DURATION / LAG_DT))):
        memory, out = control.pid_step(memory, speed, LAG_STEP, state, vehicle, vehicle.pid, LAG_DT)
        state = dynamics.step(state, np.array([out.thrust, out.rudder]), vehicle, still, LAG_DT)
        behind = state[dynamics.X] * math.sin(LAG_STEP) - state[dynamics.Y] * math.cos(LAG_STEP)
        worst = max(worst, behind)
    return worst / (speed * math.sin(LAG_STEP))


def course_tip_clearance(x, y, psi, speed, u_sub: float, horizon, length: float, diameter: float):
    """Tip clearance [m] of a UUV at (x, y) flying heading psi at `speed` through the water for
    `horizon` seconds, at GUARD_COURSE_POINTS times from 0 (the pose turned in place) to `horizon`
    along a new last axis: over the hull frame it moves at (speed cos psi - U_sub, speed sin psi)
    (docs/design.md, "Frames, units and signs"; no sway)."""
    x, y, psi, speed, horizon = (np.asarray(a, dtype=float)[..., None] for a in (x, y, psi, speed, horizon))
    tau = np.linspace(0.0, 1.0, GUARD_COURSE_POINTS) * horizon
    return tip_clearance(x + (speed * np.cos(psi) - u_sub) * tau, y + speed * np.sin(psi) * tau, psi, length, diameter)


def guard_heading_offset(
    x,
    y,
    psi_track,
    commanded,
    previous,
    length: float,
    diameter: float,
    clearance,
    max_step,
    speed,
    u_sub: float,
    horizon,
):
    """Limit (6.1)'s offset `commanded` [rad] in rate, to `max_step` [rad] (the rate limit times the
    helm's period) from `previous`, and saturate it so that the UUV at (x, y), flying psi_track +
    offset at `speed` [m/s] for `horizon` [s] (`course_lag`) beside the submarine moving at `u_sub`,
    keeps its tips `clearance` [m] off the hull (`course_tip_clearance`). Element-wise over vehicles;
    the clearance wins over the rate limit (an offset that is no longer safe is cut at once).

    The offset is allowed from 0 towards the command while the tips' clearance at each point of the
    course stays at least min(clearance, its value there at no offset): where the track itself
    already brings a tip closer than `clearance`, the compensation may not bring it closer still."""
    x, y, psi_track, commanded, previous, speed, horizon = np.broadcast_arrays(
        *(np.asarray(a, dtype=float) for a in (x, y, psi_track, commanded, previous, speed, horizon))
    )
    fractions = np.linspace(0.0, 1.0, GUARD_SAMPLES + 1)
    offsets = commanded[..., None] * fractions
    gap = course_tip_clearance(
        x[..., None],
        y[..., None],
        psi_track[..., None] + offsets,
        speed[..., None],
        u_sub,
        horizon[..., None],
        length,
        diameter,
    )
    # Each point of a candidate's course against min(clearance, the course without offset there).
    margin = (gap - np.minimum(clearance, gap[..., :1, :])).min(axis=-1)
    unsafe = margin < 0.0
    first = np.where(unsafe.any(axis=-1), np.argmax(unsafe, axis=-1), GUARD_SAMPLES + 1)
    active = first <= GUARD_SAMPLES
    last = np.clip(first - 1, 0, GUARD_SAMPLES)
    after = np.clip(first, 0, GUARD_SAMPLES)
    m0 = np.take_along_axis(margin, last[..., None], axis=-1)[..., 0]
    m1 = np.take_along_axis(margin, after[..., None], axis=-1)[..., 0]
    f0, f1 = fractions[last], fractions[after]
    drop = np.where(m0 > m1, m0 - m1, 1.0)
    crossing = f0 + (f1 - f0) * np.clip(m0 / drop, 0.0, 1.0)
    limit = np.where(active, commanded * crossing, np.copysign(np.inf, commanded))
    rated = np.clip(commanded, previous - max_step, previous + max_step)
    beyond = active & (np.abs(rated) > np.abs(limit)) & (np.sign(rated) == np.sign(commanded))
    guarded = np.where(beyond, limit, rated)
    return GuardedOffset(guarded, limit, active, guarded != commanded)
