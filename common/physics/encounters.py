"""Encounters between UUVs: the clearance between two hulls, collisions and close calls.

Each UUV is approximated by a capsule (a sphere swept along a segment): its axis from nose to
tail, of the vehicle's length L and diameter D (common/physics/vehicles.py), shortened by D/2 at
each end, with radius D/2, so its tips are the nose and tail and its widest section is the hull's.
The CB sits `hull.explorer_cb_from_nose` behind the nose (docs/design.md, "Frames, units and
signs"). The capsule contains the Explorer profile, which tapers towards both ends, so the
clearance it gives is never more than the hulls' own (it errs towards reporting an encounter).
The clearance of two capsules is the distance between their axis segments minus both radii;
it is zero or negative when they touch or overlap (a collision). A close call is a clearance of
at most one diameter of the larger UUV, the distance thesis section 5.11.2 uses for a close call
with the submarine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nearsub.common.physics.hull import explorer_cb_from_nose


@dataclass(frozen=True)
class Capsule:
    """A UUV's capsule in its body frame: the axis from `ahead` (m, towards the nose) to
    `behind` (m, towards the tail) of the CB, and the radius."""

    ahead: float
    behind: float
    radius: float

    @classmethod
    def of(cls, length: float, diameter: float) -> Capsule:
        nose = explorer_cb_from_nose(length, diameter)
        radius = diameter / 2
        return cls(nose - radius, length - nose - radius, radius)

    def axis(self, x: np.ndarray, y: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The axis segments' two ends, (n, 2) each, at CBs (x, y), headings psi (arrays (n,))."""
        direction = np.stack([np.cos(psi), np.sin(psi)], axis=-1)
        centre = np.stack([x, y], axis=-1)
        return centre + self.ahead * direction, centre - self.behind * direction


def reach(capsule: Capsule) -> float:
    """The largest distance from the CB to the capsule's surface."""
    return max(capsule.ahead, capsule.behind) + capsule.radius


def near_pairs(x: np.ndarray, y: np.ndarray, reaches: np.ndarray, margin: float) -> list[tuple[int, int]]:
    """The pairs (i < j) of UUVs whose clearance may be `margin` or less: their CBs are within
    both reaches plus the margin (the others cannot be, so the exact clearance is skipped)."""
    i, j = np.triu_indices(len(x), k=1)
    apart = np.hypot(x[i] - x[j], y[i] - y[j]) - reaches[i] - reaches[j]
    near = apart <= margin
    return list(zip(i[near].tolist(), j[near].tolist(), strict=True))


def segment_distances(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Least distances (n,) between the segments p0-p1 and q0-q1 in the plane (ends (n, 2)). Two
    segments that do not cross are closest at an end of one of them, so the least of the four
    end-to-segment distances is the answer; crossing segments are at distance 0."""
    ends = np.minimum.reduce(
        [_point_segment(p0, q0, q1), _point_segment(p1, q0, q1), _point_segment(q0, p0, p1), _point_segment(q1, p0, p1)]
    )
    return np.where(_cross(p0, p1, q0, q1), 0.0, ends)


def _point_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab, ap = b - a, p - a
    span = ab[:, 0] * ab[:, 0] + ab[:, 1] * ab[:, 1]
    along = ap[:, 0] * ab[:, 0] + ap[:, 1] * ab[:, 1]
    s = np.clip(np.divide(along, span, out=np.zeros_like(span), where=span != 0.0), 0.0, 1.0)
    return np.hypot(*(a + s[:, None] * ab - p).T)


def _cross(p0, p1, q0, q1) -> np.ndarray:
    """Whether the segments properly cross (touching ends count through the distances)."""

    def side(a, b, c):
        return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])

    d1, d2 = side(q0, q1, p0), side(q0, q1, p1)
    d3, d4 = side(p0, p1, q0), side(p0, p1, q1)
    return (d1 * d2 < 0) & (d3 * d4 < 0)


def clearances(a: Capsule, poses_a: np.ndarray, b: Capsule, poses_b: np.ndarray) -> np.ndarray:
    """Clearances [m] (n,) between two UUVs at poses (n, 3) of x, y, psi: axis distance minus both
    radii, at every row at once (a log's approaches measure whole tracks)."""
    poses_a, poses_b = np.atleast_2d(poses_a), np.atleast_2d(poses_b)
    distance = segment_distances(*a.axis(*poses_a.T), *b.axis(*poses_b.T))
    return distance - a.radius - b.radius


def clearance(a: Capsule, pose_a: tuple[float, float, float], b: Capsule, pose_b: tuple[float, float, float]) -> float:
    """Clearance [m] between two UUVs at poses (x, y, psi)."""
    return float(clearances(a, np.asarray(pose_a, float), b, np.asarray(pose_b, float))[0])


@dataclass(frozen=True)
class Encounter:
    """Two UUVs at one instant: their clearance, and whether it is a collision or a close call."""

    clearance: float
    collision: bool
    close_call: bool


def classify_pair(a: Capsule, pose_a, b: Capsule, pose_b) -> Encounter:
    """Collision at zero clearance or less; close call within one diameter of the larger UUV."""
    gap = clearance(a, pose_a, b, pose_b)
    close_limit = 2 * max(a.radius, b.radius)
    return Encounter(gap, gap <= 0.0, 0.0 < gap <= close_limit)
