"""Mission files: TOML validated by pydantic, with `--set key=value` overrides.

A broken mission file gives one `MissionError` line naming the file, the field and the value.
Headings in mission files are the psi of docs/design.md, "Frames, units and signs", in degrees
(from +x towards +y); MOOS compass headings convert as psi = 90 deg - heading.
"""

from __future__ import annotations

import difflib
import functools
import math
import os
import re
import stat
import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from nearsub.common.autonomy import helm as ivphelm
from nearsub.common.autonomy import logic
from nearsub.common.autonomy.behaviours import MAX_SPEED, Coordinate, Leg, Speed
from nearsub.common.physics import dynamics
from nearsub.common.physics.vehicles import Vehicle, get_vehicle
from nearsub.common.runtime import keys
from nearsub.common.runtime.clock import MAX_WARP
from nearsub.common.runtime.endpoints import endpoint_problem
from nearsub.common.runtime.lifecycle import Fleet, Schedule
from nearsub.common.runtime.messages import describe_validation_error

COMMUNITY_PATTERN = re.compile(r"^[A-Za-z0-9_\-]+$")
# A Zenoh locator as a mission may name it: protocol/address, with a port for the IP protocols.


def _key_chunk(value: str) -> str:
    if not COMMUNITY_PATTERN.match(value):
        raise ValueError("must contain only letters, digits, '_' and '-' (it is a key-expression chunk)")
    return value


# A community or vehicle name: one chunk of the key expressions.
KeyChunk = Annotated[str, AfterValidator(_key_chunk)]


def _vehicle_chunk(value: str) -> str:
    if value in keys.SERVICES:
        raise ValueError(f"{value!r} is a mission-wide key chunk; give the vehicle another name")
    return value


# A vehicle's name, which stands where a service's name would (nearsub/<c>/<vehicle>/...).
VehicleChunk = Annotated[KeyChunk, AfterValidator(_vehicle_chunk)]


class MissionError(ValueError):
    """A mission file that cannot be used; the message names the file, field and value."""


class Strict(BaseModel):
    """No unknown fields, and no NaN or infinity in any number."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class Network(Strict):
    """Where the apps meet. By default (`connect` empty) the launcher starts its own router on a
    free loopback port and every app connects to it as a client. `connect` points the apps, the
    logger and the tools at existing Zenoh endpoints instead: a `nearsub router` (or zenohd) on
    this or another host, or a Zenoh peer that routes for clients. Multicast scouting stays off;
    endpoints are always explicit (docs/design.md, "Transport"). `credentials` names the
    `user:password` file such a router requires (mode 0600; relative to the working directory);
    the launcher's own router gets fresh random credentials instead."""

    connect: list[str] = Field(default_factory=list)
    credentials: str | None = None

    @field_validator("connect")
    @classmethod
    def _locators(cls, value: list[str]) -> list[str]:
        for endpoint in value:
            if problem := endpoint_problem(endpoint):
                raise ValueError(problem)
        return value


class Start(Strict):
    x: Coordinate = 0.0
    y: Coordinate = 0.0
    psi_deg: float = Field(default=0.0, ge=-360.0, le=360.0)
    speed: Speed = 0.0


class Environment(Strict):
    u_sub: Speed = Field(default=0.0, description="submarine speed through the water [m/s]")
    rho: float = Field(default=1025.0, gt=0, description="sea water density [kg/m^3]")
    submarine: bool = Field(default=True, description="a submarine at the frame origin (collision checks)")
    sea_state: int = Field(default=0, ge=0, le=6, description="thesis table 5.1")
    depth: float = Field(default=50.0, gt=0, description="UUV operating depth [m] (wave decay)")
    wave_heading_deg: float = Field(default=0.0, description="direction the waves travel, psi convention")

    def dynamics(self) -> dynamics.Environment:
        """The dynamics module's view of it."""
        return dynamics.Environment(self.u_sub, self.sea_state, self.depth, math.radians(self.wave_heading_deg))


class AppSettings(Strict):
    period: int = Field(default=1, ge=1, description="runs every `period` base steps")


BEHAVIOURS = ("waypoints", "modified_waypoints", "nuv_compensation", "modified_waypoints+nuv_compensation")


VARIABLE_PATTERN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class ModeSettings(Strict):
    """One hierarchical mode rule, pHelmIvP's `set VARIABLE = VALUE { VARIABLE = PARENT; condition
    ... } ELSE_VALUE` (`logic.ModeRule`)."""

    variable: str = "MODE"
    value: str = Field(min_length=1)
    parent: str = Field(default="", description="applies while the variable equals this ('' = top level)")
    condition: list[str] = Field(default_factory=list)
    else_value: str | None = None

    @field_validator("condition")
    @classmethod
    def _parsable(cls, value: list[str]) -> list[str]:
        return logic.check_conditions(value)

    def rule(self) -> logic.ModeRule:
        conditions = tuple(logic.parse_condition(c) for c in self.condition)
        return logic.ModeRule(self.variable, self.value, self.parent or None, conditions, self.else_value)


class HelmSettings(AppSettings):
    """The helm (docs/design.md, "The helm"). Either one legacy behaviour (`behaviour` with
    `legs`): the standard waypoints (thesis 5.7), the modified waypoints (6.3.2), N_uv
    compensation (6.3.1) on top of the standard waypoints, or both composed; or a list of
    `behaviours` arbitrated by priority, with mission `variables` and `modes`. With a list,
    `behaviour` only says whether the N_uv compensation modifies the chosen heading (a name ending
    in "nuv_compensation")."""

    period: int = Field(default=5, ge=1)
    behaviour: Literal[BEHAVIOURS] = "waypoints"
    behaviours: list[ivphelm.BehaviourSpec] = Field(default_factory=list)
    variables: dict[str, str | float | bool] = Field(default_factory=dict)
    modes: list[ModeSettings] = Field(default_factory=list)
    max_speed: float | None = Field(
        default=None, gt=0, le=MAX_SPEED, description="top of the decision grid [m/s]; default the vehicle's"
    )
    alpha: float = Field(default=1.0, ge=0.0, le=1.0, description="modified waypoints: alpha of (6.2)")
    gamma: float | None = Field(default=None, gt=0, description="N_uv compensation gain; default from (6.4)")
    # The guard on (6.1)'s offset (behaviours.guard_heading_offset). Default clearance: one UUV
    # diameter, the close-call distance of thesis section 5.11.2, so the compensation itself never
    # steers a tip into a close call. Default rate: 5 deg/s, nearsub's choice: a 5 deg offset
    # builds up over 1 s instead of within one helm step, where N_s can change sign.
    guard_clearance: float | None = Field(
        default=None, ge=0, description="N_uv compensation: least tip clearance from the hull [m]; default D_uuv"
    )
    guard_rate_deg: float = Field(default=5.0, gt=0, description="N_uv compensation: largest offset rate [deg/s]")
    legs: list[Leg] = Field(default_factory=list)

    @field_validator("variables")
    @classmethod
    def _names(cls, value: dict) -> dict:
        for name in value:
            if not VARIABLE_PATTERN.match(name):
                raise ValueError(f"variable name {name!r} is not letters, digits and '_'")
        return value

    @model_validator(mode="after")
    def _one_form(self) -> HelmSettings:
        if self.behaviours and self.legs:
            raise ValueError("give either legs (one waypoints behaviour) or a list of behaviours, not both")
        names = [spec.name for spec in self.behaviours]
        if len(set(names)) != len(names):
            raise ValueError(f"behaviour names must be unique (got {names})")
        return self

    def form_error(self) -> str | None:
        """Why this helm cannot fly a vehicle: it has neither legs nor behaviours (allowed only in
        a fleet's shared `[apps.helm]`, which each vehicle completes)."""
        if not self.behaviours and not self.legs:
            return "give the waypoint legs, or a list of behaviours"
        return None

    def behaviour_specs(self) -> list:
        """The behaviours the helm arbitrates: the list, or the legacy behaviour as one waypoints
        behaviour that completes the mission with its last waypoint."""
        if self.behaviours:
            return list(self.behaviours)
        spec = ivphelm.WaypointsSpec(
            type="waypoints",
            name=self.behaviour,
            legs=self.legs,
            modified=self.behaviour.startswith("modified_waypoints"),
            alpha=self.alpha,
            endflag={ivphelm.MISSION: "complete"},
        )
        return [spec]

    @property
    def modified(self) -> bool:
        return any(getattr(spec, "modified", False) for spec in self.behaviour_specs())

    @property
    def compensated(self) -> bool:
        return self.behaviour.endswith("nuv_compensation")


class PidSettings(AppSettings):
    form: Literal["positional", "incremental"] = "positional"


class SimSettings(AppSettings):
    integrator: Literal["euler", "rk4"] = "euler"
    interaction: Literal["replace", "increment", "thesis", "off"] = Field(
        default="increment",
        description="how the surrogate's forces enter the dynamics near the submarine (dynamics.Interaction)",
    )
    divergence_speed: float = Field(default=50.0, gt=0, description="|u| beyond this ends the mission [m/s]")
    surrogate: Literal["server", "in_process"] = Field(
        default="server",
        description=(
            "where the sim app evaluates the surrogate: 'server' asks the surrogate server once per "
            "step; 'in_process' loads the same model file into the sim process (no round trip, the same "
            'forces bit for bit; docs/architecture.md, "Where the sim evaluates the surrogate")'
        ),
    )


class SurrogateSettings(Strict):
    model: str = Field(default="", description="model file; empty = the shipped model")
    viscous: bool = Field(
        default=True,
        description=(
            "in increment mode, take the interaction towards RANS near the RANS stations with the model's "
            "viscous correction, where it has one (docs/hydro/rans/README.md); false flies the panel-trained "
            "increment alone"
        ),
    )


class LoggerSettings(Strict):
    enabled: bool = True


class Apps(Strict):
    helm: HelmSettings = Field(default_factory=HelmSettings)
    pid: PidSettings = Field(default_factory=PidSettings)
    sim: SimSettings = Field(default_factory=SimSettings)
    logger: LoggerSettings = Field(default_factory=LoggerSettings)


# The vehicle types a fleet entry may name (common/physics/vehicles.py).
VEHICLE_TYPES = ("remus100", "nps_auv_ii", "sdv")


class VehicleApps(Strict):
    """A fleet vehicle's own apps: the mission's `[apps.helm]`, `.pid` and `.sim` with the
    vehicle's `[vehicles.apps.*]` merged over them (`overlay`: key by key, behaviours and legs by
    name)."""

    helm: HelmSettings = Field(default_factory=HelmSettings)
    pid: PidSettings = Field(default_factory=PidSettings)
    sim: SimSettings = Field(default_factory=SimSettings)

    @field_validator("helm")
    @classmethod
    def _flies(cls, value: HelmSettings) -> HelmSettings:
        if error := value.form_error():
            raise ValueError(error)
        return value


class FleetVehicle(Strict):
    """One `[[vehicles]]` entry: its name is the key chunk nearsub/<community>/<name>/..."""

    name: VehicleChunk
    type: Literal[VEHICLE_TYPES]
    start: Start = Field(default_factory=Start)
    apps: dict[str, Any] = Field(default_factory=dict, description="the vehicle's own [vehicles.apps.*], as written")
    # Its apps' full settings, the mission's merged under its own (`Mission._vehicle_apps`);
    # left out of dumps, so a dump validates again to the same mission.
    settings: VehicleApps = Field(default_factory=VehicleApps, exclude=True)


def overlay(base: dict, top: dict) -> dict:
    """`top` over `base` key by key: tables merge; the `behaviours` (each has a name) merge by
    name, an entry of `top` over the one of the same name in `base`, a new name after them; any
    other value of `top` (legs and lists in general) replaces the one of `base`."""
    merged = dict(base)
    for key, value in top.items():
        old = merged.get(key)
        if isinstance(old, dict) and isinstance(value, dict):
            merged[key] = overlay(old, value)
        elif key == "behaviours" and _named(old) and _named(value):
            mine = {item["name"]: item for item in value}
            kept = [overlay(item, mine.pop(item["name"], {})) for item in old]
            merged[key] = kept + list(mine.values())
        else:
            merged[key] = value
    return merged


def _named(value: Any) -> bool:
    """An array of tables that all have a name (as behaviours must)."""
    return isinstance(value, list) and all(isinstance(v, dict) and isinstance(v.get("name"), str) for v in value)


# The most steps a mission may have (a nearsub choice): 1,585 years at dt = 0.05 s, and step
# numbers far inside the 64-bit integers msgpack carries.
MAX_STEPS = 10**12


class Mission(Strict):
    name: KeyChunk = Field(description="community name: the key-expression prefix nearsub/<name>/...")
    description: str = ""
    vehicle: str | Vehicle = "remus100"
    dt: float = Field(default=0.05, gt=0, le=1.0, description="base step [s]")
    time_limit: float = Field(default=600.0, gt=0, description="simulated seconds")
    warp: float = Field(default=0.0, ge=0, le=MAX_WARP, description="0 = as fast as possible, 1 = real time")
    step_timeout: float = Field(default=10.0, gt=0, description="wall seconds an app may take per step")
    startup_timeout: float = Field(default=30.0, gt=0)
    seed: int = 0
    pause_at_step: int | None = Field(
        default=None, ge=0, description="the clock pauses before this step until resumed (swap, inspection)"
    )
    start: Start = Field(default_factory=Start)
    environment: Environment = Field(default_factory=Environment)
    network: Network = Field(default_factory=Network)
    surrogate: SurrogateSettings = Field(default_factory=SurrogateSettings)
    vehicles: list[FleetVehicle] = Field(default_factory=list, description="several vehicles (a fleet)")
    apps: Apps

    @model_validator(mode="before")
    @classmethod
    def _vehicle_apps(cls, data: Any) -> Any:
        """Each fleet vehicle's helm, pid and sim settings: the mission's `[apps.*]` with the
        vehicle's own merged over them (`overlay`), validated as the entry's `settings`."""
        if not isinstance(data, dict) or not isinstance(data.get("vehicles"), list):
            return data
        shared = data.get("apps", {})
        shared = shared if isinstance(shared, dict) else {}
        vehicles = []
        for entry in data["vehicles"]:
            own = entry.get("apps", {}) if isinstance(entry, dict) else None
            if isinstance(own, dict):
                merged = {
                    app: overlay(shared.get(app) or {}, own.get(app) or {})
                    if isinstance(shared.get(app) or {}, dict) and isinstance(own.get(app) or {}, dict)
                    else own.get(app)
                    for app in ("helm", "pid", "sim")
                }
                entry = {**entry, "settings": {**own, **merged}}
            vehicles.append(entry)
        return {**data, "vehicles": vehicles}

    @field_validator("vehicles")
    @classmethod
    def _unique_names(cls, value: list[FleetVehicle], info) -> list[FleetVehicle]:
        names = [entry.name for entry in value]
        if twice := next((name for name in names if names.count(name) > 1), None):
            raise ValueError(f"vehicle name {twice!r} is given twice")
        vehicle, start = info.data.get("vehicle", "remus100"), info.data.get("start", Start())
        if value and (vehicle != "remus100" or start != Start()):
            given = f"vehicle = {vehicle!r}" if vehicle != "remus100" else f"[start] {start}"
            raise ValueError(f"give each vehicle its type and start in its entry, not the mission's {given}")
        return value

    @field_validator("time_limit")
    @classmethod
    def _countable(cls, value: float, info) -> float:
        dt = info.data.get("dt")
        if dt and not value / dt <= MAX_STEPS:
            raise ValueError(f"{value / dt:.3g} steps of dt = {dt:g} s: at most {MAX_STEPS:.0e}")
        return value

    @field_validator("vehicle", mode="before")
    @classmethod
    def _name_or_table(cls, value: Any) -> Any:
        """Neither: one error naming the field, not one per member of the union."""
        if not isinstance(value, (str, dict, Vehicle)):
            raise ValueError("expected a vehicle name (such as 'remus100') or a [vehicle] table")
        return value

    @field_validator("vehicle")
    @classmethod
    def _known_vehicle(cls, value: str | Vehicle) -> str | Vehicle:
        if isinstance(value, str):
            try:
                get_vehicle(value)
            except KeyError as exc:
                raise ValueError(str(exc.args[0])) from None
        return value

    @field_validator("apps")
    @classmethod
    def _helm_flies(cls, value: Apps, info) -> Apps:
        """A single vehicle's helm must fly it; a fleet's `[apps.helm]` is the shared part of its
        vehicles' helms, which each entry completes (checked there)."""
        if not info.data.get("vehicles") and (error := value.helm.form_error()):
            raise ValueError(f"helm: {error}")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> Mission:
        if not math.isfinite(self.dt * self.time_limit):
            raise ValueError("dt and time_limit must be finite")
        for member in self.members():
            helm = member.apps.helm
            if helm.modified and self.environment.u_sub <= 0:
                what = "a modified waypoints behaviour"
                if not helm.behaviours:
                    what = f"apps.helm.behaviour = {helm.behaviour!r}"
                raise ValueError(
                    f"{what} steers against the submarine's cross-flow "
                    f"and needs environment.u_sub > 0 (got {self.environment.u_sub})"
                )
        return self

    def members(self) -> list[Mission]:
        """The mission as each of its vehicles sees it: for a fleet, one single-vehicle mission per
        `[[vehicles]]` entry (its type, start and merged apps, and the entry itself, whose name is
        the key chunk); without `[[vehicles]]`, the mission itself. The app cores take these."""
        return [self.member(entry.name) for entry in self.vehicles] if self.vehicles else [self]

    def member(self, name: str | None) -> Mission:
        """One vehicle's mission (see `members`); `name` None for a mission without a fleet."""
        if name is None and not self.vehicles:
            return self
        entry = next((e for e in self.vehicles if e.name == name), None)
        if entry is None:
            known = ", ".join(self.vehicle_names) or "none: it has no [[vehicles]]"
            raise KeyError(f"no vehicle named {name!r} (the mission's vehicles: {known})")
        apps = self.apps.model_copy(update=dict(entry.settings))
        return self.model_copy(update={"vehicle": entry.type, "start": entry.start, "apps": apps, "vehicles": [entry]})

    @property
    def fleet(self) -> bool:
        """Whether the mission names its vehicles (`[[vehicles]]`): apps and keys carry the names."""
        return bool(self.vehicles)

    @property
    def vehicle_names(self) -> list[str]:
        """The vehicle chunk of every vehicle's key expressions, in mission order."""
        return [entry.name for entry in self.vehicles] if self.vehicles else [self.vehicle_model.name]

    @property
    def vehicle_model(self) -> Vehicle:
        return self.vehicle if isinstance(self.vehicle, Vehicle) else get_vehicle(self.vehicle)

    @property
    def vehicle_name(self) -> str:
        """The vehicle chunk of the key expressions (of a fleet: its only vehicle; a mission of
        several vehicles has one per member)."""
        names = self.vehicle_names
        if len(names) > 1:
            raise ValueError(f"mission {self.name!r} has several vehicles ({', '.join(names)}): take its members()")
        return names[0]

    @property
    def needs_surrogate(self) -> bool:
        """A submarine is near, and a sim adds its interaction forces or a helm compensates."""
        return self.environment.submarine and any(
            m.apps.sim.interaction != "off" or m.apps.helm.compensated for m in self.members()
        )

    @property
    def max_steps(self) -> int:
        return int(round(self.time_limit / self.dt))

    def periods(self) -> dict[str, int]:
        return {"helm": self.apps.helm.period, "pid": self.apps.pid.period, "sim": self.apps.sim.period}

    def lockstep(self) -> Fleet:
        """The lock-step of the mission's vehicles, each under its own periods (one vehicle named
        None without [[vehicles]], whose apps keep their bare role names)."""
        return Fleet({(m.vehicle_name if self.fleet else None): Schedule(m.periods()) for m in self.members()})


def parse_override(text: str) -> tuple[list[str], Any]:
    """'a.b=value' -> (['a', 'b'], value); the value is read as TOML, else kept as a string."""
    if "=" not in text:
        raise MissionError(f"--set {text!r}: expected key=value")
    key, raw = text.split("=", 1)
    key = key.strip()
    if not key or "" in key.split("."):
        raise MissionError(f"--set {text!r}: empty key" if not key else f"--set {text!r}: empty part in key {key!r}")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    except RecursionError:
        raise MissionError(f"--set {key}: value nested too deeply") from None
    return key.split("."), value


def apply_overrides(data: dict, overrides: list[str]) -> dict:
    """Set each dotted key; `vehicles.NAME.` continues in the `[[vehicles]]` entry named NAME
    (MissionError naming it when there is none)."""
    for text in overrides:
        path, value = parse_override(text)
        node = data
        parts = iter(path[:-1])
        for part in parts:
            child = node.get(part)
            if part == "vehicles" and node is data:
                name = next(parts, path[-1])
                child = vehicle_entry(data, name, text)
                if name == path[-1]:
                    raise MissionError(
                        f"--set {text}: give a setting of vehicle {name!r}, e.g. vehicles.{name}.start.y=12"
                    )
            elif not isinstance(child, dict):
                child = {}
                node[part] = child
            node = child
        node[path[-1]] = value
    return data


def vehicle_entry(data: dict, name: str, text: str) -> dict:
    """The `[[vehicles]]` entry named `name` of a raw mission; MissionError naming it."""
    entries = data.get("vehicles")
    entries = entries if isinstance(entries, list) else []
    for entry in entries:
        if isinstance(entry, dict) and entry.get("name") == name:
            return entry
    known = ", ".join(str(e.get("name")) for e in entries if isinstance(e, dict)) or "none: it has no [[vehicles]]"
    raise MissionError(f"--set {text}: no vehicle named {name!r} (the mission's vehicles: {known})")


def read_toml(path: Path) -> dict:
    """One TOML file as a dict; MissionError naming the file. Only a regular file is read: a
    FIFO or a device would block or never end (opened without blocking, then checked)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        raise MissionError(f"{path}: cannot read mission file ({exc.strerror})") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise MissionError(f"{path}: not a regular file (a mission file is a TOML text file)")
    with os.fdopen(fd, "rb") as source:
        try:
            text = source.read().decode("utf-8")
        except OSError as exc:
            raise MissionError(f"{path}: cannot read mission file ({exc.strerror})") from None
        except UnicodeDecodeError as exc:
            raise MissionError(
                f"{path}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset {exc.start})"
            ) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MissionError(f"{path}: not valid TOML ({exc})") from None
    except RecursionError:
        raise MissionError(f"{path}: not valid TOML (arrays or tables nested too deeply)") from None


def merge(base: dict, top: dict) -> dict:
    """`top` over `base`: tables merge key by key, arrays of tables are concatenated (base first,
    so shared behaviours come before the mission's own), any other value of `top` wins."""
    merged = dict(base)
    for key, value in top.items():
        old = merged.get(key)
        if isinstance(old, dict) and isinstance(value, dict):
            merged[key] = merge(old, value)
        elif isinstance(old, list) and isinstance(value, list) and all(isinstance(v, dict) for v in old + value):
            merged[key] = old + value
        else:
            merged[key] = value
    return merged


def resolve_includes(path: Path, chain: tuple[Path, ...] = ()) -> dict:
    """A mission file with its `include = ["shared.toml", ...]` resolved (relative to the file
    that includes them, in order, each under the including file's own settings), recursively.
    MissionError on a cycle or a missing file, naming the chain."""
    here = path.resolve()
    if here in chain:
        cycle = " -> ".join(str(p) for p in (*chain, here))
        raise MissionError(f"{path}: include cycle ({cycle})")
    data = read_toml(path)
    includes = data.pop("include", [])
    if isinstance(includes, str):
        includes = [includes]
    if not isinstance(includes, list) or not all(isinstance(i, str) for i in includes):
        raise MissionError(f"{path}: include: expected a list of file names, got {includes!r}")
    base: dict = {}
    for name in includes:
        target = path.parent / name
        if not target.is_file():
            raise MissionError(f"{path}: include {name!r}: no such file {target}")
        base = merge(base, resolve_includes(target, (*chain, here)))
    return merge(base, data)


def file_setting(path: Path, loc: list[str]) -> Path | None:
    """The file of the include tree of `path` whose own text sets the field at `loc` (or the
    array holding it), the one whose value the merge keeps; None if none does."""
    data = read_toml(path)
    includes = data.pop("include", [])
    node = data
    for part in loc:
        if isinstance(node, list):
            return path  # an array of tables: merged from several files, named by the first
        if not isinstance(node, dict) or part not in node:
            break
        node = node[part]
    else:
        return path
    for name in reversed([includes] if isinstance(includes, str) else includes):
        if found := file_setting(path.parent / name, loc):
            return found
    return None


# The missions that ship with nearsub (missions/ of the source tree), by name.
SHIPPED_MISSIONS = Path(__file__).resolve().parents[2] / "missions"


def mission_path(target: str | Path) -> Path:
    """A mission file by its path, or a shipped mission by its name (`alpha`: missions/alpha.toml)
    when no file of that name is here. MissionError for a bare name that is neither, naming the
    shipped ones."""
    path = Path(target)
    if path.exists() or path.suffix or len(path.parts) > 1:
        return path
    shipped = SHIPPED_MISSIONS / f"{path}.toml"
    if shipped.is_file():
        return shipped
    names = ", ".join(sorted(p.stem for p in SHIPPED_MISSIONS.glob("*.toml"))) or "none"
    raise MissionError(f"{target}: no such mission file, nor a shipped mission (shipped: {names})")


def load_mission(path: str | Path, overrides: list[str] = ()) -> Mission:
    """Read (with its includes), override and validate a mission file."""
    path = Path(path)
    data = resolve_includes(path)
    apply_overrides(data, list(overrides))
    if data.get("vehicles") == []:  # a saved mission (a run file) may hold [], a user's file not
        source = next((f"--set {o}" for o in reversed(overrides) if parse_override(o)[0] == ["vehicles"]), path)
        raise MissionError(f"{source}: field 'vehicles' = []: leave [[vehicles]] out for a single-vehicle mission")
    return mission_from_dict(data, str(path), overrides, lambda loc: str(file_setting(path, loc) or path))


def mission_from_dict(data: dict, where: str = "mission", overrides: list[str] = (), file_of=None) -> Mission:
    """Validate a mission; an error names `where` (with `file_of(loc)`, the file of the include
    tree that set the bad field), or the `--set` override that gave the bad value."""
    try:
        return Mission.model_validate(data)
    except ValidationError as exc:
        name = _vehicle_names(data)
        source = _source_of(exc, where, overrides, name)
        if source == where and file_of is not None:
            source = file_of([str(p) for p in exc.errors()[0]["loc"]])
        text = describe_validation_error(exc, source, name, _did_you_mean)
        raise MissionError(text) from None


def _did_you_mean(item: dict) -> str:
    """For a field the schema does not have: the closest field names at its place (difflib)."""
    if item["type"] != "extra_forbidden":
        return ""
    close = difflib.get_close_matches(str(item["loc"][-1]), _field_names(tuple(item["loc"][:-1])), n=2, cutoff=0.7)
    return f" (did you mean {' or '.join(repr(c) for c in close)}?)" if close else ""


@functools.cache
def _field_names(loc: tuple) -> list[str]:
    """The field names the mission schema allows inside `loc` (its JSON schema walked along the
    path, through references, lists and every branch of a union); all its field names where the
    walk loses its way."""
    schema = Mission.model_json_schema()
    definitions = schema.get("$defs", {})

    def expand(node: dict) -> list[dict]:
        if "$ref" in node:
            return expand(definitions[node["$ref"].rsplit("/", 1)[-1]])
        branches = node.get("anyOf") or node.get("oneOf")
        return [leaf for branch in branches for leaf in expand(branch)] if branches else [node]

    nodes = expand(schema)
    for part in loc:
        inner = []
        for node in nodes:
            if isinstance(part, int) and "items" in node:
                inner += expand(node["items"])
            elif part in node.get("properties", {}):
                inner += expand(node["properties"][part])
            elif node.get("properties", {}).get("type", {}).get("const") == part:  # a union's tag
                inner.append(node)
        nodes = inner
    names = sorted({name for node in nodes for name in node.get("properties", {})})
    return names or sorted({name for node in (schema, *definitions.values()) for name in node.get("properties", {})})


def _vehicle_names(data: dict):
    """Error locations as users write them: `vehicles.NAME...` for the entry's index, and the
    names alone for the vehicles list itself (a duplicate name)."""
    entries = data.get("vehicles") if isinstance(data, dict) else None
    entries = entries if isinstance(entries, list) else []

    def name(loc: tuple, value):
        if loc[:1] != ("vehicles",):
            return loc, value
        if len(loc) == 1:
            return loc, [e.get("name") if isinstance(e, dict) else e for e in entries] if entries else value
        index, rest = loc[1], loc[2:]
        rest = ("apps", *rest[1:]) if rest[:1] == ("settings",) else rest  # what the user wrote
        entry = entries[index] if isinstance(index, int) and index < len(entries) else None
        if isinstance(entry, dict) and isinstance(entry.get("name"), str):
            return ("vehicles", entry["name"], *rest), value
        return ("vehicles", index, *rest), value

    return name


def _source_of(error: ValidationError, where: str, overrides: list[str], name=lambda loc, value: (loc, value)) -> str:
    """`--set KEY=VALUE` when a bad field lies at or below an override's key, or above it (the
    override made it the wrong type), also within a fleet vehicle's copy of the mission's
    `[apps.*]` (`vehicles.NAME.apps...`); else `where`."""
    locs = []
    for item in error.errors():
        loc = [str(p) for p in name(tuple(item["loc"]), None)[0]]
        locs += [loc, loc[2:]] if loc[:1] == ["vehicles"] and loc[2:3] == ["apps"] else [loc]
    for text in reversed(list(overrides)):  # the last override of a key wins, as in apply_overrides
        path, _ = parse_override(text)
        if any(loc and (loc[: len(path)] == path or path[: len(loc)] == loc) for loc in locs):
            return f"--set {text}"
    return where


class RunConfig(Strict):
    """What the launcher hands every app it starts: the resolved mission and where to connect."""

    mission: Mission
    connect: list[str]
    log_dir: str = ""

    @classmethod
    def load(cls, path: str | Path) -> RunConfig:
        return cls.model_validate_json(Path(path).read_text())

    def save(self, path: str | Path) -> None:
        Path(path).write_text(self.model_dump_json(indent=2))
