"""nearsub's sim in a MOOS community: the mapping between MOOS variables and the sim's input,
state, forces and events, and MOOS time against the sim's steps (docs/moos.md).

Frames. MOOS's local grid has x east, y north, headings in compass degrees (0 = north,
clockwise). nearsub's x and y are MOOS's x and y, and nearsub's psi (from +x towards +y,
docs/design.md "Frames, units and signs") is the mathematical angle, so heading = 90 - psi in
degrees. nearsub's frame moves with the submarine along +x at U_sub: a point (x, y) of that
frame is at (x + x_0 + U_sub t, y + y_0) on the MOOS grid, with (x_0, y_0) the submarine's CB when
the sim starts (`submarine_pos`). Without a submarine (U_sub = 0) the frames are the same.

Actuators (uSimMarineV22's inputs). DESIRED_THRUST is percent of the vehicle's thrust limit
(`Vehicle.max_thrust`, nearsub's vehicle library), clipped to [-100, 100]: X_prop =
thrust / 100 * max_thrust. DESIRED_RUDDER is the rudder angle in degrees, clipped at the
vehicle's limit (`Vehicle.max_rudder`): a positive rudder turns the bow clockwise (heading
increases), as in uSimMarineV22, which is nearsub's positive delta_r (N_uudr < 0, Prestero
2001). DESIRED_ELEVATOR is accepted and ignored: the dynamics are 3-DOF, horizontal plane.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from nearsub.common.moos.config import Datum

EARTH_RADIUS = 6378137.0  # WGS-84 equatorial radius [m] (NIMA TR8350.2, 2000, table 3.1)

HULL_STATIONS = 40  # per side of the hull's outline: its outline to a few centimetres, a short post
ACTUATOR_VARIABLES = ("DESIRED_THRUST", "DESIRED_RUDDER", "DESIRED_ELEVATOR")


def compass_heading(psi: float) -> float:
    """nearsub's psi [rad] as a MOOS heading [deg, 0 = north, clockwise, in [0, 360)]."""
    return (90.0 - math.degrees(psi)) % 360.0


def psi_of_heading(heading: float) -> float:
    """A MOOS compass heading [deg] as nearsub's psi [rad]."""
    return math.radians(90.0 - heading)


def moos_yaw(heading: float) -> float:
    """NAV_YAW as uSimMarineV22 posts it: -radians(heading in [-180, 180)) (SimEngine.cpp)."""
    return -math.radians((heading + 180.0) % 360.0 - 180.0)


def local_to_geodetic(x: float, y: float, datum: Datum) -> tuple[float, float]:
    """(lat, lon) [deg] of the local grid point (x east, y north) [m]: the flat-earth
    (equirectangular) projection about the datum, good to centimetres over the few kilometres
    of a mission (MOOS's MOOSGeodesy uses UTM, which agrees to the same order there)."""
    lat = datum.lat + math.degrees(y / EARTH_RADIUS)
    lon = datum.lon + math.degrees(x / (EARTH_RADIUS * math.cos(math.radians(datum.lat))))
    return lat, lon


@dataclass
class Actuators:
    """The latest DESIRED_* values, as uSimMarineV22 keeps them (no timeout: the last value
    holds), and the malformed ones seen (ignored, counted, reported)."""

    thrust: float = 0.0  # percent
    rudder: float = 0.0  # degrees
    elevator: float = 0.0  # degrees (not used by the 3-DOF dynamics)
    malformed: dict[str, int] = field(default_factory=dict)
    last_malformed: str = ""

    def receive(self, name: str, value) -> bool:
        """Take one DESIRED_* mail (a double, or a string holding a number, as uPokeDB may post);
        anything else is ignored and counted. Returns whether it was used."""
        try:
            number = float(value)
        except (TypeError, ValueError):
            number = math.nan
        if not math.isfinite(number) or isinstance(value, bool):
            self.malformed[name] = self.malformed.get(name, 0) + 1
            self.last_malformed = f"{name}={value!r}"
            return False
        attribute = {"DESIRED_THRUST": "thrust", "DESIRED_RUDDER": "rudder", "DESIRED_ELEVATOR": "elevator"}[name]
        setattr(self, attribute, number)
        return True

    def command(self, vehicle) -> tuple[float, float]:
        """(X_prop [N], delta_r [rad]) within the vehicle's limits."""
        thrust = min(max(self.thrust, -100.0), 100.0)
        rudder = min(max(math.radians(self.rudder), -vehicle.max_rudder), vehicle.max_rudder)
        return thrust / 100.0 * vehicle.max_thrust, rudder


@dataclass(frozen=True)
class Placement:
    """Where nearsub's moving frame is on the MOOS grid: the submarine's CB at `origin` when the
    sim starts (MOOS time t0), moving east at u_sub."""

    origin: tuple[float, float]
    u_sub: float

    def to_moos(self, x: float, y: float, t: float) -> tuple[float, float]:
        return x + self.origin[0] + self.u_sub * t, y + self.origin[1]

    def from_moos(self, x: float, y: float, t: float) -> tuple[float, float]:
        return x - self.origin[0] - self.u_sub * t, y - self.origin[1]


def nav_variables(state, t: float, placement: Placement, datum: Datum | None, prefix: str = "NAV") -> dict:
    """What uSimMarineV22 posts of the vehicle: X, Y, HEADING, SPEED (surge through the water,
    which is still on the MOOS grid), DEPTH (0: a horizontal-plane model), YAW, and LAT/LONG with a
    datum."""
    x, y = placement.to_moos(state.x, state.y, t)
    heading = compass_heading(state.psi)
    out = {
        f"{prefix}_X": x,
        f"{prefix}_Y": y,
        f"{prefix}_HEADING": heading,
        f"{prefix}_SPEED": state.u,
        f"{prefix}_DEPTH": 0.0,
        f"{prefix}_YAW": moos_yaw(heading),
    }
    if datum is not None:
        out[f"{prefix}_LAT"], out[f"{prefix}_LONG"] = local_to_geodetic(x, y, datum)
    return out


def node_report(
    name: str,
    x: float,
    y: float,
    heading: float,
    speed: float,
    t: float,
    kind: str,
    length: float | None,
    color: str = "",
) -> str:
    """A NODE_REPORT line as pNodeReporter writes it (NodeRecord::getSpec); no LENGTH if None."""
    text = f"NAME={name},X={x:.2f},Y={y:.2f},SPD={speed:.2f},HDG={heading:.2f},DEP=0,TYPE={kind},TIME={t:.2f}"
    text += "" if length is None else f",LENGTH={length:g}"
    return text + (f",COLOR={color}" if color else "")


def submarine_report(t: float, moos_time: float, placement: Placement) -> str:
    """The submarine as a contact at sim time t, stamped `moos_time`: its CB, heading east (90),
    at u_sub. No LENGTH: pMarineViewer would draw its own ship icon that long, about three times
    the hull's beam, over the hull's outline; without it the icon is a marker at the CB."""
    x, y = placement.to_moos(0.0, 0.0, t)
    return node_report("submarine", x, y, 90.0, placement.u_sub, moos_time, "ship", None, "gray")


def hull_seglist(xs, ys, t: float, placement: Placement, label: str = "submarine_hull") -> str:
    """A closed outline given in nearsub's frame as a VIEW_SEGLIST, placed on the MOOS grid at t.
    Not a VIEW_POLYGON: pMarineViewer drops non-convex polygons, and SUBOFF's afterbody is
    concave (its convex hull is 1 % larger, off by most at the stern, where the overtakes collide)."""
    placed = (placement.to_moos(a, b, t) for a, b in zip(xs, ys, strict=True))
    points = ":".join(f"{px:.2f},{py:.2f}" for px, py in placed)
    return f"pts={{{points}}},label={label},edge_color=white,edge_size=2,vertex_size=0"


def forces_variables(forces) -> dict:
    """NEARSUB_* variables of one `Forces` message: the interaction (N, N m) and its flags."""
    return {
        "NEARSUB_X_S": forces.X_s,
        "NEARSUB_Y_S": forces.Y_s,
        "NEARSUB_N_S": forces.N_s,
        "NEARSUB_IN_DOMAIN": "true" if forces.in_domain else "false",
        "NEARSUB_CONSTRAINTS_OK": "true" if forces.constraints_ok else "false",
        "NEARSUB_WEIGHT": forces.weight,
    }


def event_variables(kind: str, detail: str) -> dict:
    """An event as MOOS variables: NEARSUB_EVENT always, and NEARSUB_CLOSE_CALL or
    NEARSUB_COLLISION for the proximity events (their detail text)."""
    out = {"NEARSUB_EVENT": f"kind={kind},detail={detail}"}
    if kind in ("close_call", "collision"):
        out[f"NEARSUB_{kind.upper()}"] = detail
    return out


@dataclass
class MoosClock:
    """MOOS time against the sim's steps: step k is due once MOOS time reaches t0 + k dt. MOOS
    time is the wall clock times MOOSTimeWarp, so the sim honours the warp by stepping as many
    times as MOOS time has advanced, whatever its AppTick."""

    t0: float
    dt: float

    def due(self, moos_now: float, done: int) -> int:
        """How many steps to run now, having run `done`."""
        return max(0, math.floor((moos_now - self.t0) / self.dt + 1e-9) - done)

    def moos_time(self, step: int) -> float:
        return self.t0 + step * self.dt


def appcast(proc: str, node: str, iteration: int, status: dict, events: list[str], warnings: dict[str, int]) -> str:
    """The APPCAST string uMAC and pMarineViewer read (AppCast::getAppCastString in MOOS's
    AppCasting library): the status table as its messages, the last events, and the run warnings
    with their counts (the malformed DESIRED_* values)."""
    outer, inner = "!@#", "!@"
    messages = inner.join(f"{key:<24} {value}" for key, value in status.items())
    shown = events[-8:]
    fields = [
        f"proc={proc}",
        f"iter={iteration}",
        f"node={node}",
        f"iter={iteration}",
        f"messages={messages}{inner if messages else ''}",
        "",  # no config warnings
        f"events_total={len(shown)}",
        f"events={inner.join(shown)}" if shown else "",
        f"run_warning_total={sum(warnings.values())}",
    ]
    if warnings:
        fields.append("run_warnings=" + inner.join(f"{count}:{text}" for text, count in sorted(warnings.items())))
    return outer.join(fields) + ("" if warnings else outer)
