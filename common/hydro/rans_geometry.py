"""Hull surfaces for the RANS fidelity (docs/hydro/rans/README.md): closed triangulated STL bodies
of revolution from the project's own profiles (physics/hull.py), placed in the case's frame.

Frames: a body's surface is built in its body frame (origin at its CB, the volume centroid, x
towards the bow) and placed at (x, y, 0) turned by psi about z, as in high_fidelity
(`Mesh.placed`). The whole closed body is written; the domain's z = 0 symmetry plane cuts it in
snappyHexMesh.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from nearsub.common.physics.hull import Profile, explorer_profile, suboff_profile

STATIONS = 240  # meridian stations, arc-length spaced and clustered at the tips (hull.place_stations)
AZIMUTHS = 96  # facets round the axis: chord sagitta 0.05 % of the radius, far below the finest surface cell


@dataclass(frozen=True)
class Body:
    """One hull of a case: its patch name, its profile (body frame) and its placement."""

    patch: str
    hull: str  # "suboff-model", "suboff-full" or "explorer"
    length: float
    diameter: float
    x: float = 0.0  # CB position in the case frame [m]
    y: float = 0.0
    psi: float = 0.0  # heading [rad], from +x towards +y

    def profile(self, stations: int = STATIONS) -> Profile:
        if self.hull == "suboff-model":
            return suboff_profile(stations, model_scale=True)
        if self.hull == "suboff-full":
            return suboff_profile(stations)
        if self.hull == "explorer":
            return explorer_profile(stations, self.length, self.diameter)
        raise ValueError(f"unknown hull {self.hull!r}")

    @property
    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Body x and y axes in the case frame (3-vectors)."""
        c, s = np.cos(self.psi), np.sin(self.psi)
        return np.array([c, s, 0.0]), np.array([-s, c, 0.0])

    @property
    def centre(self) -> np.ndarray:
        return np.array([self.x, self.y, 0.0])

    def ends(self) -> np.ndarray:
        """Bow and stern tips (2, 3) in the case frame."""
        p = self.profile(40)
        e_x, _ = self.axes
        return np.array([self.centre + (p.cb - p.s[0]) * e_x, self.centre + (p.cb - p.s[-1]) * e_x])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box (lo, hi) of the whole body in the case frame."""
        points = self.triangles(60, 24).reshape(-1, 3)
        return points.min(axis=0), points.max(axis=0)

    def triangles(self, stations: int = STATIONS, azimuths: int = AZIMUTHS) -> np.ndarray:
        """Closed surface (n, 3, 3), outward normals (counter-clockwise seen from outside)."""
        return self._place(revolution_triangles(self.profile(stations), azimuths))

    def _place(self, points: np.ndarray) -> np.ndarray:
        e_x, e_y = self.axes
        rot = np.column_stack([e_x, e_y, [0.0, 0.0, 1.0]])
        return points @ rot.T + self.centre


def revolution_triangles(profile: Profile, azimuths: int = AZIMUTHS) -> np.ndarray:
    """Closed triangulation (n, 3, 3) of a body of revolution in its body frame: rings at the
    profile's stations, fans to the axis at the two tips (the profile's first and last radius are
    zero: both hulls end in points)."""
    r = profile.r.copy()
    r[0] = r[-1] = 0.0
    x = profile.x
    # Half a facet off the planes y = 0 and z = 0, so that no vertex lies on a symmetry plane of
    # the domain (snappyHexMesh misses edge intersections exactly in a facet's plane).
    theta = np.linspace(0.0, 2.0 * np.pi, azimuths, endpoint=False) + np.pi / azimuths
    ring = np.stack(np.broadcast_arrays(x[:, None], r[:, None] * np.cos(theta), r[:, None] * np.sin(theta)), axis=-1)
    nxt = np.roll(np.arange(azimuths), -1)
    tris = []
    # Stations run nose (+x) to tail and theta turns from +y to +z, so (a, c, b) is outward.
    tris.append(np.stack([ring[0, :], ring[1, :], ring[1, nxt]], axis=1))  # nose fan
    for i in range(1, len(x) - 2):
        a, b = ring[i, :], ring[i, nxt]
        c, d = ring[i + 1, :], ring[i + 1, nxt]
        tris.append(np.stack([a, c, b], axis=1))
        tris.append(np.stack([b, c, d], axis=1))
    tris.append(np.stack([ring[-2, :], ring[-1, :], ring[-2, nxt]], axis=1))  # tail fan
    return np.concatenate(tris)


def enclosed_volume(triangles: np.ndarray) -> float:
    """Volume enclosed by a closed, outward-oriented triangulation (divergence theorem)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    return float(np.sum(np.einsum("ij,ij->i", a, np.cross(b, c))) / 6.0)


def open_edges(triangles: np.ndarray) -> int:
    """Edges not shared by exactly two triangles in opposite directions (0 for a closed surface)."""
    points, index = np.unique(triangles.reshape(-1, 3).round(12), axis=0, return_inverse=True)
    faces = index.reshape(-1, 3)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = edges[edges[:, 0] != edges[:, 1]]  # degenerate tip edges
    forward = {tuple(e) for e in edges}
    return sum(1 for e in edges if (e[1], e[0]) not in forward) + (len(edges) - len(forward))


def write_stl(path, triangles: np.ndarray, name: str) -> None:
    """Binary STL (snappyHexMesh reads it by its extension and detects binary)."""
    t = np.asarray(triangles, dtype=np.float64)
    normals = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1), 1e-300)[:, None]
    records = np.zeros(len(t), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    records["n"], records["v"] = normals, t
    with open(path, "wb") as f:
        f.write(name.encode()[:80].ljust(80, b" "))
        f.write(struct.pack("<I", len(t)))
        f.write(records.tobytes())


def read_stl(path) -> np.ndarray:
    """Triangles (n, 3, 3) of a binary STL written by `write_stl`."""
    data = open(path, "rb").read()
    (count,) = struct.unpack("<I", data[80:84])
    records = np.frombuffer(data[84:], dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")], count=count)
    return records["v"].astype(float)
