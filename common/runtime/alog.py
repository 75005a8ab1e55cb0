"""A mission log as a MOOS-IvP alog: what pLogger writes, so alogview, aloggrep and alogsort read it
(docs/design.md, "MOOS-IvP conventions").

The format is the one moos-ivp's log utilities parse (`ivp/src/lib_logutils/LogUtils.cpp`): a
banner of `%%` lines as pLogger's `DoBanner` writes it, with `%% LOGSTART <epoch>` within the first
five lines; then one line per posting, `TIME VARIABLE SOURCE VALUE`, separated by blanks, TIME in
seconds since LOGSTART, one variable per line, the value a number or text (text may hold blanks).
Lines are sorted by time; postings at the same time keep the order of the log.

What each topic becomes (MOOS units: compass degrees, 0 = north = +y, clockwise, in [0, 360)):

- state   -> NAV_X, NAV_Y [m], NAV_HEADING = 90 - psi [deg], NAV_SPEED = u [m/s], NAV_YAW =
  -radians(angle180(NAV_HEADING)) as uSimMarine posts it, and NODE_REPORT_LOCAL / NODE_REPORT
  (`NAME=..,X=..,Y=..,SPD=..,HDG=..,DEP=0,TYPE=UUV,TIME=<epoch>,LENGTH=..`, as pNodeReporter;
  NAME is the mission's name for one vehicle, each vehicle's name (its key chunk) for several,
  as a MOOS fleet's shoreside alog holds every node's reports);
- desired -> DESIRED_HEADING [compass deg], DESIRED_SPEED [m/s];
- input   -> DESIRED_RUDDER = delta_r [deg] (positive turns to starboard, as MOOS's rudder: it
  raises the compass heading), DESIRED_THRUST = 100 X_prop / max_thrust, the percent of the
  vehicle's thrust limit pMarinePID posts (left out for a vehicle the log does not describe);
- helm    -> WPT_INDEX, IVPHELM_BHV_ACTIVE (the behaviour);
- forces  -> INTERACTION_X, INTERACTION_Y [N], INTERACTION_N [N m], what the dynamics applied;
- events  -> EVENT_<KIND> (EVENT_WAYPOINT, EVENT_COLLISION, ...), the event's text (the mission's
  events and a vehicle's apps', nearsub/<c>/events/<vehicle>/<instance>);
- clock/end -> MISSION (the outcome) and MISSION_REASON; control requests -> CONTROL_REQUEST;
- DB_TIME from `MOOSDB_<community>` once per simulated second: alogview names the vehicle after
  that source, as a MOOSDB names itself MOOSDB_<community>. One vehicle's alog (`vehicle`) is
  that vehicle's community: MOOSDB_<vehicle>, its records and the mission-wide ones, so alogview
  given one such file per vehicle shows the fleet.

The clock's ticks and acks, app status and replies are the lock-step's own traffic and are left
out; a payload the logger could not decode becomes INVALID_MESSAGE naming its topic.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, TextIO

from nearsub.common.runtime.logfile import INVALID_SUFFIX, vehicle_spec

if TYPE_CHECKING:
    from nearsub.common.runtime.logfile import LogContents, LogRecord

# A vehicle library by name (physics.vehicles.get_vehicle, which the caller passes: the runtime knows
# no physics): anything with `length` [m] and `max_thrust` [N]; KeyError for an unknown name.
VehicleLibrary = Callable[[str], Any]

BANNER_RULE = "%" * 59  # pLogger's DoBanner rule line


def compass_deg(psi: float) -> float:
    """nearsub's psi [rad, from +x towards +y] as a MOOS compass heading in [0, 360)."""
    heading = (90.0 - math.degrees(psi)) % 360.0
    return 0.0 if heading >= 360.0 else heading


def angle180(deg: float) -> float:
    """An angle in degrees brought into (-180, 180], as MOOS's angle180."""
    a = math.fmod(deg, 360.0)
    if a > 180.0:
        a -= 360.0
    elif a <= -180.0:
        a += 360.0
    return a


def number(value: float) -> str:
    """A double as pLogger-style text: up to 6 decimals, trailing zeros dropped."""
    if not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def log_start(contents: LogContents) -> float:
    """The epoch the mission started at: the logger's start time, else the earliest wall-clock
    receive time less its simulated time, else 0."""
    started = contents.metadata.get("run", {}).get("started_unix")
    if started:
        try:
            return float(started)
        except ValueError:
            pass
    starts = [(r.publish_time - r.log_time) / 1e9 for r in contents.records if r.publish_time]
    return min(starts) if starts else 0.0


def _community(contents: LogContents) -> str:
    name = contents.metadata.get("mission", {}).get("name")
    if name:
        return name
    for r in contents.records:
        parts = r.topic.split("/")
        if len(parts) > 2:
            return parts[1]
    return "nearsub"


def _vehicle_figures(vehicle: str, contents: LogContents, library: VehicleLibrary) -> dict[str, float]:
    """The vehicle's length [m] and thrust limit [N], from the log's mission (a vehicle given
    by name or in full, or its `[[vehicles]]` entry) or `library`; an empty dict when neither
    knows it."""
    resolved = contents.metadata.get("mission", {}).get("resolved")
    try:
        spec = vehicle_spec(json.loads(resolved), vehicle) if resolved else None
    except ValueError:
        spec = None
    if isinstance(spec, dict) and spec.get("length") and spec.get("max_thrust"):
        return {"length": float(spec["length"]), "max_thrust": float(spec["max_thrust"])}
    try:
        model = library(spec if isinstance(spec, str) else vehicle)
    except KeyError:
        return {}
    return {"length": model.length, "max_thrust": model.max_thrust}


class _Lines:
    def __init__(self):
        self.entries: list[tuple[int, int, str, str, str]] = []  # (log_time ns, order, var, src, value)

    def post(self, log_time: int, variable: str, source: str, value: str) -> None:
        value = value.replace("\n", " ").replace("\r", " ").strip() or "-"
        source = "".join(source.split()) or "nearsub"
        self.entries.append((log_time, len(self.entries), variable, source, value))


def alog_lines(
    contents: LogContents,
    library: VehicleLibrary,
    records: Iterable[LogRecord] | None = None,
    vehicle: str | None = None,
) -> list[str]:
    """The alog's lines (banner included, no newlines) for `records` (default: every record);
    `library` gives the length and thrust limit of a vehicle the log's mission names only by name.
    With several vehicles, each NODE_REPORT names its vehicle (NAME=<vehicle>, as a shoreside's
    alog); `vehicle` writes that vehicle's own alog (`LogContents.vehicle_records`), whose MOOSDB is named
    after it, as alogview reads one alog per vehicle."""
    records = contents.records if records is None else list(records)
    if vehicle is not None:
        records = contents.vehicle_records(vehicle, records)
    start = log_start(contents)
    mission = _community(contents)
    community = mission if vehicle is None else vehicle  # a vehicle's own alog: its own MOOS community
    lines = _Lines()
    known: dict[str, dict[str, float]] = {}

    def figures(vehicle: str) -> dict[str, float]:
        if vehicle not in known:
            known[vehicle] = _vehicle_figures(vehicle, contents, library)
        return known[vehicle]

    vehicles = set(contents.vehicles())
    if records:
        first = min(r.log_time for r in records) // 1_000_000_000
        last = max(r.log_time for r in records) // 1_000_000_000
        for s in range(first, last + 1):
            lines.post(s * 1_000_000_000, "DB_TIME", f"MOOSDB_{community}", number(start + s))
    for r in records:
        _translate(r, lines, start, community, vehicles, figures, contents)
    lines.entries.sort(key=lambda e: (e[0], e[1]))
    out = [
        BANNER_RULE,
        f"%% LOG FILE:       {community}.alog (nearsub mission {mission})",
        f"%% FILE OPENED ON  {time.asctime(time.gmtime(start))}",
        f"%% LOGSTART        {start:>20.12g}",
        BANNER_RULE,
        "%% Exported by nearsub log export --format alog. NAV_HEADING and DESIRED_HEADING are compass",
        "%% degrees (90 - psi), DESIRED_RUDDER degrees, DESIRED_THRUST percent of the thrust limit, NAV_SPEED the",
        "%% surge u through the water; positions are in the mission's frame (the submarine frame).",
    ]
    for log_time, _, variable, source, value in lines.entries:
        out.append(f"{log_time / 1e9:<14.3f} {variable:<20} {source:<12} {value}")
    return out


def write_alog(
    contents: LogContents,
    out: TextIO,
    library: VehicleLibrary,
    records: Iterable[LogRecord] | None = None,
    vehicle: str | None = None,
) -> int:
    """Write the alog (of one `vehicle`, see `alog_lines`) to `out`; returns the number of postings
    (lines after the banner)."""
    lines = alog_lines(contents, library, records, vehicle)
    for line in lines:
        out.write(line + "\n")
    return sum(1 for line in lines if not line.startswith("%"))


def _translate(r: LogRecord, lines: _Lines, start: float, community: str, vehicles, figures, contents) -> None:
    t = r.log_time
    parts = r.topic.split("/")
    if r.topic.endswith(INVALID_SUFFIX):
        lines.post(t, "INVALID_MESSAGE", "logger", r.topic.removesuffix(INVALID_SUFFIX))
        return
    if len(parts) < 3:
        return
    value = r.value()
    if not isinstance(value, dict):
        return
    source = str(value.get("source") or (parts[-1] if parts[2] == "events" else parts[2]))
    rest = parts[2:]
    if rest[0] == "events":
        kind = str(value.get("kind", "info")).upper()
        lines.post(t, f"EVENT_{kind}", source, str(value.get("detail") or value.get("kind", "")))
    elif rest[0] == "clock":
        if len(rest) >= 2 and rest[1] == "end":
            lines.post(t, "MISSION", source, str(value.get("outcome", "")))
            if value.get("reason"):
                lines.post(t, "MISSION_REASON", source, str(value["reason"]))
    elif rest[0] == "control":
        args = ",".join(f"{k}={v}" for k, v in (value.get("args") or {}).items())
        target = "/".join(rest[1:])
        text = f"target={target},cmd={value.get('cmd', '')}" + (f",{args}" if args else "")
        lines.post(t, "CONTROL_REQUEST", source, text)
    elif len(rest) == 2:
        vehicle, leaf = rest
        if leaf == "state":
            _state(t, value, source, vehicle, lines, start, community, vehicles, figures, contents)
        elif leaf == "desired":
            lines.post(t, "DESIRED_HEADING", source, number(compass_deg(value["psi_d"])))
            lines.post(t, "DESIRED_SPEED", source, number(value["u_d"]))
        elif leaf == "input":
            lines.post(t, "DESIRED_RUDDER", source, number(math.degrees(value["delta_r"])))
            limit = figures(vehicle).get("max_thrust")
            if limit:  # pMarinePID posts the percent of the thrust limit
                lines.post(t, "DESIRED_THRUST", source, number(100.0 * value["X_prop"] / limit))
        elif leaf == "helm":
            lines.post(t, "WPT_INDEX", source, str(value.get("waypoint_index", 0)))
            lines.post(t, "IVPHELM_BHV_ACTIVE", source, str(value.get("behaviour", "")))
        elif leaf == "forces":
            for axis in ("X", "Y", "N"):
                lines.post(t, f"INTERACTION_{axis}", source, number(value.get(f"applied_{axis}", 0.0)))


def _state(t, value, source, vehicle, lines: _Lines, start, community, vehicles, figures, contents) -> None:
    heading = compass_deg(value["psi"])
    x, y, speed = value["x"], value["y"], value["u"]
    lines.post(t, "NAV_X", source, number(x))
    lines.post(t, "NAV_Y", source, number(y))
    lines.post(t, "NAV_HEADING", source, number(heading))
    lines.post(t, "NAV_SPEED", source, number(speed))
    lines.post(t, "NAV_YAW", source, number(-math.radians(angle180(heading))))
    name = community if len(vehicles) <= 1 else vehicle  # MOOS names a node after its vehicle
    report = (
        f"NAME={name},X={number(x)},Y={number(y)},SPD={number(speed)},HDG={number(heading)},DEP=0,"
        f"TYPE=UUV,TIME={start + t / 1e9:.3f}"
    )
    if "length" in figures(vehicle):
        report += f",LENGTH={number(figures(vehicle)['length'])}"
    lines.post(t, "NODE_REPORT_LOCAL", source, report)
    lines.post(t, "NODE_REPORT", source, report)
