"""Wire messages: pydantic models, msgpack codec and the topic -> model registry.

Every message carries the schema version, the step index it describes and the simulated time
(docs/design.md). The thesis vectors travel as named fields: state [u, v, r, x, y, psi],
desired [u_d, psi_d], input [X_prop, delta_r]. Angles are radians on the wire.

`decode` validates on receive: a malformed payload raises `MessageError` whose text names the
topic, the field and the offending value, so receivers can log it and carry on.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import msgpack
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

SCHEMA_VERSION = 1


class MessageError(ValueError):
    """A payload that is not valid msgpack or does not match its topic's schema."""


class Message(BaseModel):
    """Common header. `step` is the lock-step index the content is valid at; `t` = step * dt."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    schema_version: int = SCHEMA_VERSION
    step: int = Field(ge=0)
    t: float
    source: str = ""

    @field_validator("schema_version")
    @classmethod
    def _known_version(cls, value: int) -> int:
        if value != SCHEMA_VERSION:
            raise ValueError(f"unsupported schema_version {value} (this build speaks {SCHEMA_VERSION})")
        return value


class FiniteMessage(Message):
    """A message whose float fields must all be finite (NaN or inf never enters the physics).
    One model-wide setting checked inside pydantic's core, not a Python validator per field
    (which made a State decode several times dearer); the error still names the field."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class State(FiniteMessage):
    """Vehicle state x = [u, v, r, x, y, psi]: velocities relative to the water, position in the
    submarine frame (docs/design.md, "Frames, units and signs")."""

    u: float
    v: float
    r: float
    x: float
    y: float
    psi: float


class Desired(FiniteMessage):
    """Desired state x_d = [u_d, psi_d] from the helm."""

    u_d: float
    psi_d: float


class Input(FiniteMessage):
    """Actuator input u = [X_prop, delta_r] from the PID (newtons, radians). The bounds only
    reject absurd values (a rudder beyond +/-180 deg); the sim saturates at the vehicle's limits."""

    X_prop: float = Field(ge=-1e7, le=1e7)
    delta_r: float = Field(ge=-math.pi, le=math.pi)


class HelmProgress(Message):
    """What the helm is doing: behaviour, leg and waypoint index, and compensation terms. With N_uv
    compensation, delta_psi_commanded is (6.1)'s offset and delta_psi the one the helm used after
    the tip-clearance guard (`behaviours.guard_heading_offset`): guard_limit is the largest offset
    [rad] (signed, towards the submarine's side it limits) keeping the tip guard_clearance [m] off the
    hull, guard_saturated says the limit or the rate limit cut the command."""

    behaviour: str
    leg: int
    waypoint_index: int
    waypoints_reached: int
    psi_d: float
    delta_psi: float = 0.0
    cross_track: float = Field(default=0.0, description="distance to the current track-line [m]")
    n_s: float = Field(default=0.0, description="interaction yaw moment used by N_uv compensation [N m]")
    complete: bool = False
    mode: str = Field(default="", description="the helm's MODE variable (hierarchical, ':' separated)")
    active: list[str] = Field(default_factory=list, description="behaviours with an objective, by priority")
    winner: str = Field(default="", description="the behaviour whose own decision was taken, if any")
    delta_psi_commanded: float = 0.0
    guard_active: bool = False
    guard_saturated: bool = False
    guard_limit: float = math.inf
    guard_clearance: float = 0.0


class Poke(Message):
    """Mission variables an operator sets in a running helm (`nearsub poke`, uPokeDB): applied at
    the next step the helm runs, as an operator override (runtime.lifecycle.Stepper.override)."""

    values: dict[str, str | float | bool] = Field(min_length=1)

    @field_validator("values")
    @classmethod
    def _finite_values(cls, value: dict) -> dict:
        """allow_inf_nan does not reach the floats of a union inside a dict: check them here."""
        for name, number in value.items():
            if isinstance(number, float) and not math.isfinite(number):
                raise ValueError(f"{name} = {number} is not a finite number")
        return value


class Forces(Message):
    """Interaction forces on the vehicle at step `step` (frame convention, N and N m).

    X_s, Y_s, N_s: the interaction before the weight (in "increment" mode the increment);
    applied_X/Y/N = weight x X_s/Y_s/N_s, what the dynamics used at this step (in "increment" mode
    exactly what is added to (5.11)); model_X/Y/N and std_X/Y/N: the model's raw answer and its
    std (the discrepancy delta at the state clamped into table 4.2's box when the LF is in the
    loop, the prediction otherwise; NaN where the model was not asked); lf_X/Y/N: the LF increment
    LF - LF_free at the true pose and delta_weight the weight of delta (NaN when the mode does not
    use them). in_domain and constraints_ok: table 4.2 and (4.4)-(4.7); `outside` names every
    input and constraint the state is outside of; lf_held: the LF held its field at 1 cm from the
    submarine's widest radius (`low_fidelity.lf_increment_terms`); viscous_X/Y/N: the viscous
    correction's part of X_s/Y_s/N_s (`surrogate.viscous`; zero without one)."""

    X_s: float
    Y_s: float
    N_s: float
    std_X: float
    std_Y: float
    std_N: float
    weight: float
    in_domain: bool
    constraints_ok: bool
    applied_X: float = 0.0
    applied_Y: float = 0.0
    applied_N: float = 0.0
    model_X: float = math.nan
    model_Y: float = math.nan
    model_N: float = math.nan
    lf_X: float = math.nan
    lf_Y: float = math.nan
    lf_N: float = math.nan
    delta_weight: float = math.nan
    outside: list[str] = Field(default_factory=list)
    lf_held: bool = False
    viscous_X: float = 0.0
    viscous_Y: float = 0.0
    viscous_N: float = 0.0


class Tick(Message):
    """The clock's go-ahead for step `step`."""


class Ack(Message):
    """An app has finished step `step`. `end` asks the clock to end the mission after this step
    with that outcome (e.g. "completed" from the helm, "collision" from the sim)."""

    end: str | None = None
    reason: str = ""


class MissionEnd(Message):
    """Published once by the clock: the mission is over; apps leave their loops."""

    outcome: str
    reason: str = ""


EventKind = Literal[
    "waypoint",
    "collision",
    "close_call",
    "large_stray",
    "saturation",
    "app_joined",
    "app_left",
    "swap",
    "error",
    "info",
]


class Event(Message):
    """Something people watch for: waypoints, collisions, app joins, swaps, errors."""

    kind: EventKind
    detail: str = ""
    data: dict[str, Any] = Field(default_factory=dict)


class Control(Message):
    """A request to one app instance (or the clock): pause, resume, status, handover, retire.
    Control travels as ordinary messages so it is ordered with the data and logged."""

    cmd: str
    args: dict[str, Any] = Field(default_factory=dict)
    request_id: str
    reply_to: str


class ControlReply(Message):
    request_id: str
    ok: bool
    data: dict[str, Any] = Field(default_factory=dict)
    error: str = ""


class AppStatus(Message):
    """An app's lifecycle state, published on start-up and on the way out."""

    app: str
    instance: str
    state: Literal["starting", "running", "stopping"]


def encode(message: Message) -> bytes:
    """Serialise a message to msgpack: its fields in declaration order, read straight from the
    validated model (every field is a plain value: no nested models), the bytes of
    `model_dump` at a third of its cost."""
    return msgpack.packb(message.__dict__, use_bin_type=True)


def describe_validation_error(error: ValidationError, where: str, name=None, hint=None) -> str:
    """One line naming each bad field and its value; `name(loc, value) -> (loc, value)` may
    rename them (a mission names its vehicles by name, not by index); `hint(item)` may add to an
    error (a field name it may stand for)."""
    parts = []
    for item in error.errors():
        extra = "" if hint is None else hint(item)
        loc, value = tuple(item["loc"]), item.get("input")
        if name is not None:
            loc, value = name(loc, value)
        if not loc:  # a check of the whole message or mission: its reason alone, not the whole input
            parts.append(str(item.get("ctx", {}).get("error", item["msg"])))
            continue
        field = ".".join(str(p) for p in loc)
        # A missing field's input is its parent: the whole message or mission, which says nothing.
        parts.append(
            f"field '{field}': {item['msg']}{extra}"
            if item["type"] == "missing"
            else f"field '{field}' = {value!r}: {item['msg']}{extra}"
        )
    return f"{where}: " + "; ".join(parts)


def unpack_map(data: bytes, where: str = "message") -> dict:
    """msgpack bytes as a map of fields; raise MessageError naming the problem."""
    try:
        raw = msgpack.unpackb(data, raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises several unrelated exception types
        raise MessageError(f"{where}: not valid msgpack ({exc})") from None
    if not isinstance(raw, dict):
        raise MessageError(f"{where}: expected a map of fields, got {type(raw).__name__}")
    return raw


def decode(data: bytes, model: type[Message], where: str = "message") -> Message:
    """Parse and validate msgpack bytes as `model`; raise MessageError naming the problem."""
    raw = unpack_map(data, where)
    try:
        return model.__pydantic_validator__.validate_python(raw)
    except ValidationError as exc:
        raise MessageError(describe_validation_error(exc, where)) from None


# Topic leaf name -> model. Vehicle topics live at nearsub/<community>/<vehicle>/<leaf>.
VEHICLE_TOPICS: dict[str, type[Message]] = {
    "state": State,
    "desired": Desired,
    "input": Input,
    "helm": HelmProgress,
    "forces": Forces,
    "poke": Poke,
}


def model_for_key(key: str) -> type[Message] | None:
    """The message model of a concrete key expression, or None if the key is not ours."""
    parts = key.split("/")
    if len(parts) < 3 or parts[0] != "nearsub":
        return None
    rest = parts[2:]
    if rest[0] == "clock" and len(rest) >= 2:
        return {"tick": Tick, "ack": Ack, "end": MissionEnd}.get(rest[1])
    if rest[0] == "events":
        return Event
    if rest[0] == "control":
        return Control
    if rest[0] == "reply":
        return ControlReply
    if rest[0] == "status":
        return AppStatus
    if len(rest) == 2:
        return VEHICLE_TOPICS.get(rest[1])
    return None


# Short keys a person types for a mission's topics (`tap echo state`, `log export --topic state`):
# each vehicle topic leaf stands for that topic of every vehicle, `events` for every event, `end`
# for the clock's end; {c} is the community.
SHORT_KEYS = {leaf: "nearsub/{c}/*/" + leaf for leaf in VEHICLE_TOPICS} | {
    "events": "nearsub/{c}/events/**",
    "end": "nearsub/{c}/clock/end",
}


def short_key(name: str, community: str | None = None) -> str | None:
    """The key expression a short key stands for in `community` (None: in every one), or None
    when `name` is not a short key."""
    pattern = SHORT_KEYS.get(name)
    return None if pattern is None else pattern.format(c=community or "*")


ALL_MODELS: tuple[type[Message], ...] = (
    State,
    Desired,
    Input,
    HelmProgress,
    Forces,
    Poke,
    Tick,
    Ack,
    MissionEnd,
    Event,
    Control,
    ControlReply,
    AppStatus,
)
