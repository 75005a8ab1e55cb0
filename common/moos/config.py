"""A .moos file as MOOS apps read it: `KEY = VALUE` global parameters (ServerHost, ServerPort,
Community, MOOSTimeWarp, LatOrigin, LongOrigin) and `ProcessConfig = APP { KEY = VALUE ... }`
blocks; `//` starts a comment. Keys are case-insensitive, as in MOOS. A line that is neither is a
`MoosConfigError` naming the file, the line and its text."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path


class MoosConfigError(ValueError):
    """A .moos line nearsub cannot use: the text names the file, the line number and the line."""


@dataclass(frozen=True)
class Entry:
    line: int
    key: str  # lower case
    value: str


@dataclass
class MoosFile:
    path: str
    globals: dict[str, Entry] = field(default_factory=dict)
    blocks: dict[str, list[Entry]] = field(default_factory=dict)

    def global_value(self, key: str, default: str | None = None) -> str | None:
        entry = self.globals.get(key.lower())
        return default if entry is None else entry.value

    def error(self, entry: Entry, problem: str) -> MoosConfigError:
        return MoosConfigError(f"{self.path}:{entry.line}: {entry.key} = {entry.value}: {problem}")


def parse_moos(text: str, path: str = "<moos>") -> MoosFile:
    """Global parameters and every ProcessConfig block of a .moos file's text."""
    moos = MoosFile(path)
    block: list[Entry] | None = None
    opening: str | None = None  # a ProcessConfig line waiting for its "{"
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("//", 1)[0].strip()
        if not line:
            continue
        if opening is not None:
            if line != "{":
                problem = f"expected '{{' after ProcessConfig = {opening}"
                raise MoosConfigError(f"{path}:{number}: {raw.strip()!r}: {problem}")
            block, opening = moos.blocks.setdefault(opening, []), None
            continue
        if line == "}" and block is not None:
            block = None
            continue
        key, sep, value = line.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or " " in key:
            raise MoosConfigError(f"{path}:{number}: {raw.strip()!r}: expected KEY = VALUE")
        if block is None and key.lower() == "processconfig":
            opening = value
            continue
        entry = Entry(number, key.lower(), value)
        if block is None:
            moos.globals[entry.key] = entry
        else:
            block.append(entry)
    if opening is not None or block is not None:
        raise MoosConfigError(f"{path}: the ProcessConfig block {opening or ''} is not closed with '}}'")
    return moos


def read_moos(path: str | Path) -> MoosFile:
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise MoosConfigError(f"{path}: {exc.strerror or exc}") from None
    return parse_moos(text, str(path))


@dataclass(frozen=True)
class Datum:
    """LatOrigin/LongOrigin: the local grid's origin (NAV_X = NAV_Y = 0) in degrees."""

    lat: float
    lon: float


@dataclass
class SimConfig:
    """The `ProcessConfig = nearsub_sim` block (uSimMarineV22's names where they exist).

    mission: a nearsub mission file for the vehicle, environment, surrogate and dt (relative to
    the .moos file); every other key overrides it. start_pos: uSimMarine's
    `x=, y=, heading= (compass deg), speed=`. u_sub and submarine: the submarine's speed and
    whether there is one; its CB is at submarine_pos (MOOS x, y) when the sim starts, heading east
    (MOOS +x; docs/moos.md)."""

    host: str = "localhost"
    port: int = 9000
    community: str = "nearsub"
    time_warp: float = 1.0
    datum: Datum | None = None
    app_tick: float = 20.0
    comms_tick: float = 20.0
    prefix: str = "NAV"
    mission: str = ""
    overrides: list[str] = field(default_factory=list)  # `--set` style, on the mission
    start: dict[str, float] = field(default_factory=dict)  # x, y, heading, speed (MOOS)
    submarine_pos: tuple[float, float] = (0.0, 0.0)


MAX_TIME_WARP = 400.0  # MOOS's limit (MOOSUtilityFunctions.cpp, MAX_TIME_WARP)
MAX_APP_TICK = 100.0  # MOOS's CMOOSApp limit on AppTick
MAX_COMMS_TICK = 200.0  # MOOS's CMOOSApp limit on CommsTick


def number(moos: MoosFile, entry: Entry, low: float = -math.inf, high: float = math.inf) -> float:
    try:
        value = float(entry.value)
    except ValueError:
        raise moos.error(entry, "not a number") from None
    if not (math.isfinite(value) and low <= value <= high):
        raise moos.error(entry, f"outside [{low:g}, {high:g}]")
    return value


def boolean(moos: MoosFile, entry: Entry) -> bool:
    text = entry.value.lower()
    if text not in ("true", "false"):
        raise moos.error(entry, "expected true or false")
    return text == "true"


def pairs(moos: MoosFile, entry: Entry, names: tuple[str, ...]) -> dict[str, float]:
    """`x=0, y=-20, heading=180`: the named numbers (uSimMarine's start_pos syntax)."""
    values = {}
    for part in entry.value.split(","):
        name, sep, text = part.partition("=")
        name = name.strip().lower()
        if not sep or name not in names:
            raise moos.error(entry, f"{part.strip()!r}: expected NAME=VALUE with NAME one of {', '.join(names)}")
        try:
            values[name] = float(text)
        except ValueError:
            raise moos.error(entry, f"{part.strip()!r}: not a number") from None
        if not math.isfinite(values[name]):
            raise moos.error(entry, f"{part.strip()!r}: not a finite number")
    return values


# ProcessConfig key -> the mission field it sets (`--set` syntax); values checked by the schema.
MISSION_KEYS = {
    "vehicle": "vehicle",
    "dt": "dt",
    "u_sub": "environment.u_sub",
    "submarine": "environment.submarine",
    "interaction": "apps.sim.interaction",
    "integrator": "apps.sim.integrator",
    "model": "surrogate.model",
    "sea_state": "environment.sea_state",
}


def sim_config(moos: MoosFile, app: str = "nearsub_sim") -> SimConfig:
    """The sim's settings: the community's globals and the app's ProcessConfig block."""
    config = SimConfig()
    globals_ = moos.globals
    if "serverhost" in globals_:
        config.host = globals_["serverhost"].value
    if "serverport" in globals_:
        config.port = int(number(moos, globals_["serverport"], 1, 65535))
    if "community" in globals_:
        config.community = globals_["community"].value
    if "moostimewarp" in globals_:
        config.time_warp = number(moos, globals_["moostimewarp"], 1e-3, MAX_TIME_WARP)
    if "latorigin" in globals_ and "longorigin" in globals_:
        config.datum = Datum(
            number(moos, globals_["latorigin"], -90, 90), number(moos, globals_["longorigin"], -180, 180)
        )
    if app not in moos.blocks:
        raise MoosConfigError(f"{moos.path}: no ProcessConfig = {app} block")
    for entry in moos.blocks[app]:
        key = entry.key
        if key == "apptick":
            config.app_tick = number(moos, entry, 1e-3, MAX_APP_TICK)
        elif key == "commstick":
            config.comms_tick = number(moos, entry, 1e-3, MAX_COMMS_TICK)
        elif key == "prefix":
            if not entry.value.replace("_", "").isalnum():
                raise moos.error(entry, "expected letters, digits and '_'")
            config.prefix = entry.value
        elif key == "mission":
            config.mission = str(Path(moos.path).parent / entry.value)
        elif key == "start_pos":
            config.start = pairs(moos, entry, ("x", "y", "heading", "speed", "depth"))
        elif key == "submarine_pos":
            found = pairs(moos, entry, ("x", "y"))
            config.submarine_pos = (found.get("x", 0.0), found.get("y", 0.0))
        elif key in MISSION_KEYS:
            value = entry.value if key != "submarine" else str(boolean(moos, entry)).lower()
            if key in ("vehicle", "interaction", "integrator", "model"):
                value = f'"{value}"'
            config.overrides.append(f"{MISSION_KEYS[key]}={value}")
        else:
            raise moos.error(entry, f"unknown parameter (known: {', '.join(sorted(KNOWN))})")
    return config


KNOWN = {"apptick", "commstick", "prefix", "mission", "start_pos", "submarine_pos", *MISSION_KEYS}
