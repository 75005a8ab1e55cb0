"""Closest approaches of a run: each UUV's to the submarine's hull, and the closest pair of UUVs.

The hull clearance is surface to surface in the plane of both axes (the 3-DOF plane,
docs/design.md, "Frames, units and signs"): the UUV's Explorer outline against the SUBOFF
outline (common/physics/hull.py), negative when they overlap, with where on the hull the
nearest point lies (x in the submarine frame, and R_long = x / L_sub, thesis (3.3)). Between
UUVs it is the capsule clearance of common/physics/encounters.py, at the steps both states share.
The launcher's summary and `nearsub log info` both call `log_approaches` on the log.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from nearsub.common.physics import encounters, proximity
from nearsub.common.physics.hull import L_SUB, uuv_outline

# Bound on the error of proximity.closest_distance's grids (a few cm beyond 5 m of the hull,
# proximity's module notes): the poses within it of the least clearance are measured exactly.
_GRID_SLACK = 0.05  # [m]
_OUTLINE_POINTS = 64  # stations per side of the UUV outline, as proximity.classify uses


@dataclass(frozen=True)
class Track:
    """One UUV's states: steps, simulated times [s], CB x, y [m] and heading psi [rad] in the
    submarine frame, and its hull's length and diameter [m]."""

    step: np.ndarray
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    psi: np.ndarray
    length: float
    diameter: float


@dataclass(frozen=True)
class HullApproach:
    clearance: float  # least surface-to-surface distance to the hull [m]; <= 0 is contact
    t: float  # when [s]
    hull_x: float  # where: the hull point's x in the submarine frame [m] (CB origin, bow +x)

    @property
    def r_long(self) -> float:
        return self.hull_x / L_SUB


@dataclass(frozen=True)
class PairApproach:
    vehicles: tuple[str, str]
    clearance: float  # least capsule clearance between the two [m]
    t: float


@dataclass(frozen=True)
class Approaches:
    hull: dict[str, HullApproach]  # per vehicle; empty without a submarine
    pair: PairApproach | None  # the closest pair; None with one vehicle

    def as_dict(self) -> dict:
        hull = {
            name: {"clearance_m": a.clearance, "t": a.t, "hull_x_m": a.hull_x, "r_long": a.r_long}
            for name, a in self.hull.items()
        }
        pair = self.pair and {
            "vehicles": list(self.pair.vehicles),
            "clearance_m": self.pair.clearance,
            "t": self.pair.t,
        }
        return {"hull": hull, "closest_pair": pair}

    def lines(self) -> list[str]:
        """One line per vehicle and one for the pair, for people."""
        out = [
            f"{name}: closest to the hull {a.clearance:.2f} m at t={a.t:.2f} s, "
            f"beside x={a.hull_x:+.1f} m (R_long {a.r_long:+.3f})"
            for name, a in self.hull.items()
        ]
        if self.pair is not None:
            a, b = self.pair.vehicles
            out.append(f"{a} and {b}: closest {self.pair.clearance:.2f} m apart at t={self.pair.t:.2f} s")
        return out


def hull_approach(track: Track) -> HullApproach:
    """The least hull clearance of a track, when, and beside which x of the hull."""
    clearance = proximity.closest_distance(track.x, track.y, track.psi, track.length, track.diameter)
    candidates = np.flatnonzero(clearance <= clearance.min() + _GRID_SLACK)
    ox, oy = uuv_outline(
        track.x[candidates], track.y[candidates], track.psi[candidates], track.length, track.diameter, _OUTLINE_POINTS
    )
    distance, hull_x = proximity.nearest_hull_point(ox, oy)
    per_pose = distance.min(axis=-1)
    best = int(np.argmin(per_pose))
    k = int(candidates[best])
    return HullApproach(float(per_pose[best]), float(track.t[k]), float(hull_x[best, np.argmin(distance[best])]))


def pair_approach(a: str, track_a: Track, b: str, track_b: Track) -> PairApproach | None:
    """When two UUVs came closest (the first such step), at the steps both have a state (None if
    they share none): every shared step measured at once."""
    _, ia, ib = np.intersect1d(track_a.step, track_b.step, assume_unique=True, return_indices=True)
    if len(ia) == 0:
        return None
    ca = encounters.Capsule.of(track_a.length, track_a.diameter)
    cb = encounters.Capsule.of(track_b.length, track_b.diameter)
    poses_a = np.stack([track_a.x[ia], track_a.y[ia], track_a.psi[ia]], axis=-1)
    poses_b = np.stack([track_b.x[ib], track_b.y[ib], track_b.psi[ib]], axis=-1)
    gaps = encounters.clearances(ca, poses_a, cb, poses_b)
    n = int(np.argmin(gaps))
    return PairApproach((a, b), float(gaps[n]), float(track_a.t[ia[n]]))


def closest_pair(tracks: dict[str, Track]) -> PairApproach | None:
    """The pair of UUVs that came closest (None with fewer than two)."""
    names = sorted(tracks)
    found = [pair_approach(a, tracks[a], b, tracks[b]) for i, a in enumerate(names) for b in names[i + 1 :]]
    return min((p for p in found if p is not None), key=lambda p: p.clearance, default=None)


def approaches(tracks: dict[str, Track], submarine: bool) -> Approaches:
    hull = {name: hull_approach(track) for name, track in sorted(tracks.items())} if submarine else {}
    return Approaches(hull, closest_pair(tracks))


def log_approaches(contents) -> Approaches | None:
    """The approaches of a log (`runtime.logfile.LogContents`) from its states and the resolved
    mission in its metadata; None without states or without a mission this version reads."""
    from nearsub.common.mission.schema import MissionError, mission_from_dict
    from nearsub.common.runtime.keys import vehicle_topic

    resolved = contents.metadata.get("mission", {}).get("resolved")
    if not resolved:
        return None
    try:
        mission = mission_from_dict(json.loads(resolved))
    except (MissionError, ValueError):  # a mission this version cannot read: nothing to size the hulls by
        return None
    sizes = {m.vehicle_name: m.vehicle_model for m in mission.members()}
    state_keys = {vehicle_topic(mission.name, name, "state"): name for name in sizes}
    columns: dict[str, list] = {}
    for record in contents.records:
        if (name := state_keys.get(record.topic)) is not None:
            s = record.value()
            columns.setdefault(name, []).append((s["step"], s["t"], s["x"], s["y"], s["psi"]))
    tracks = {}
    for name, rows in columns.items():
        step, t, x, y, psi = (np.asarray(c) for c in zip(*sorted(rows), strict=True))
        _, first = np.unique(step, return_index=True)  # one state per step (a replayed duplicate is dropped)
        model = sizes[name]
        tracks[name] = Track(step[first], t[first], x[first], y[first], psi[first], model.length, model.diameter)
    if not tracks:
        return None
    return approaches(tracks, mission.environment.submarine)
