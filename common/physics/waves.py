"""Deep-water linear plane progressive waves, thesis (5.22)/(5.23), for sea states 0-6 (table 5.1).

The thesis wave is a 2-D field in a vertical plane: u_w along the direction of propagation and
v_w pointing down, both of amplitude omega A e^(-k d) at depth d. Section 5.8 then makes the
conservative choice to lay that plane into the 3-DOF horizontal plane, so that the component
pointing "down" (towards a submarine below) pushes the UUV towards or away from the submarine
instead of orthogonal to the plane of the two axes. nearsub implements exactly that:

- the propagation component u_w acts along the wave heading beta in the horizontal plane;
- the "down" component v_w acts along the in-plane normal that points towards the submarine's
  axis for beta = 0 (a wave running along +x pushes a UUV on the +y side towards -y at phase 0);
- on the -y side the field is mirrored (docs/design.md, "Frames, units and signs"), so both sides
  see the same worst case.

Since both components share one amplitude, the lateral (towards/away) velocity always has the full
amplitude omega A e^(-k d), whatever the heading. The phase k xi - omega t uses the position xi
along the heading measured in the water, so a submarine frame moving at U_sub sees the wave at
its encounter frequency. The submarine is assumed not to damp the waves (thesis section 5.8).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

G = 9.81  # gravitational acceleration [m/s^2]


@dataclass(frozen=True)
class SeaState:
    """One row of thesis table 5.1 (general North Atlantic)."""

    number: int
    significant_height: tuple[float, float]  # range [m]
    most_probable_period: float | None  # [s]; table 5.1 gives none for sea states 0-1

    @property
    def amplitude(self) -> float:
        """A = half the largest significant height of the range (thesis section 5.8); 0 if calm."""
        return 0.5 * self.significant_height[1] if self.most_probable_period else 0.0

    @property
    def omega(self) -> float:
        """omega = 2 pi / T at the most probable period (thesis section 5.8) [rad/s]."""
        return 2.0 * math.pi / self.most_probable_period if self.most_probable_period else 0.0

    @property
    def wavenumber(self) -> float:
        """Deep-water dispersion k = omega^2 / g (thesis section 5.8) [1/m]."""
        return self.omega**2 / G

    @property
    def wavelength(self) -> float:
        """lambda = 2 pi g / omega^2 [m] (docs/design.md, "Thesis errata" 1)."""
        return 2.0 * math.pi / self.wavenumber if self.wavenumber else math.inf

    def orbital_amplitude(self, depth):
        """Orbital velocity amplitude omega A e^(-k d) at depth d [m] (5.22, 5.23) [m/s]."""
        return self.omega * self.amplitude * np.exp(-self.wavenumber * np.asarray(depth, dtype=float))


# Thesis table 5.1 [80]. Sea states 0 and 1 share the row "0-0.1 m" with no period; nearsub
# treats them as calm (A = 0), since no omega can be formed without a period.
SEA_STATES: dict[int, SeaState] = {
    0: SeaState(0, (0.0, 0.1), None),
    1: SeaState(1, (0.0, 0.1), None),
    2: SeaState(2, (0.1, 0.5), 7.5),
    3: SeaState(3, (0.5, 1.25), 7.5),
    4: SeaState(4, (1.25, 2.5), 8.8),
    5: SeaState(5, (2.5, 4.0), 9.7),
    6: SeaState(6, (4.0, 6.0), 12.4),
}


def sea_state(number: int) -> SeaState:
    """Look up a sea state of table 5.1 (0-6)."""
    try:
        return SEA_STATES[int(number)]
    except KeyError:
        raise KeyError(f"sea state {number!r} is not in thesis table 5.1 (0-6)") from None


def orbital_velocity(x, y, t, state: SeaState, depth: float, heading: float = 0.0, u_sub: float = 0.0):
    """Wave velocity (u_wave, v_wave) in the submarine frame at positions (x, y) and time t.

    x, y [m] are submarine-frame positions (any broadcastable shapes), t [s], depth [m] the UUV's
    operating depth, heading [rad] the wave's direction of travel (from +x towards +y), u_sub
    [m/s] the submarine's speed through the water. The result adds to x' and y'
    (docs/design.md, "Frames, units and signs").
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    mirror = np.where(y < 0.0, -1.0, 1.0)  # mirror the -y side (docs/design.md, "Frames")
    cos_b, sin_b = math.cos(heading), math.sin(heading)
    xi = (x + u_sub * t) * cos_b + y * mirror * sin_b  # distance along the heading, water-fixed
    phase = state.wavenumber * xi - state.omega * t
    amp = state.orbital_amplitude(depth)
    along = amp * np.cos(phase)  # (5.22) u_w, the direction of propagation
    down = amp * np.sin(phase)  # (5.23) v_w, "down" laid towards the submarine (section 5.8)
    # Propagation unit vector (cos b, sin b); the "down" normal (sin b, -cos b) is -y at b = 0.
    u_wave = along * cos_b + down * sin_b
    v_wave = mirror * (along * sin_b - down * cos_b)
    return u_wave, v_wave
