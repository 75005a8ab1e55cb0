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

    def axis(self, x: float, y: float, psi: float) -> tuple[np.ndarray, np.ndarray]:
        """The axis segment's two ends at CB (x, y), heading psi."""
        direction = np.array([np.cos(psi), np.sin(psi)])
        centre = np.array([x, y])
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


def segment_distance(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> float:
    """Least distance between the segments p0-p1 and q0-q1 in the plane. Two segments that do not
    cross are closest at an end of one of them, so the least of the four end-to-segment
    distances is the answer; crossing segments are at distance 0."""
    if _cross(p0, p1, q0, q1):
        return 0.0
    return min(
        _point_segment(p0, q0, q1), _point_segment(p1, q0, q1), _point_segment(q0, p0, p1), _point_segment(q1, p0, p1)
    )


def _point_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    span = float(ab @ ab)
    s = 0.0 if span == 0.0 else min(max(float((p - a) @ ab) / span, 0.0), 1.0)
    return float(np.hypot(*(a + s * ab - p)))


def _cross(p0, p1, q0, q1) -> bool:
    """Whether the segments properly cross (touching ends count through the distances)."""

    def side(a, b, c) -> float:
        return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

    d1, d2 = side(q0, q1, p0), side(q0, q1, p1)
    d3, d4 = side(p0, p1, q0), side(p0, p1, q1)
    return d1 * d2 < 0 and d3 * d4 < 0


def clearance(a: Capsule, pose_a: tuple[float, float, float], b: Capsule, pose_b: tuple[float, float, float]) -> float:
    """Clearance [m] between two UUVs at poses (x, y, psi): axis distance minus both radii."""
    return segment_distance(*a.axis(*pose_a), *b.axis(*pose_b)) - a.radius - b.radius


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
