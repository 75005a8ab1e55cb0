"""The unit and frame of every field of every message (`messages.ALL_MODELS`), and the form people
read and type.

On the wire angles are radians (`messages`), positions are in the submarine frame and velocities
and forces on the vehicle's body axes (docs/design.md, "Frames, units and signs"). People read
and type angles in degrees, and a heading as the mission files give it (`psi_deg`): psi, from +x
towards +y. So `for_people` renames each angle field NAME to NAME_deg (rad/s: NAME_deg_s) with its
value in degrees, and `from_people` takes those names back to the raw fields: what `tap echo`
prints on a terminal, `tap pub` takes. docs/messages.md is `markdown_tables()` (a test keeps it
so).

The header (`schema_version`, `step`, `t`, `source`) is every message's and is listed once.
"""

from __future__ import annotations

import math

# (unit, what it is and in which frame); unit "-" for a number without one, "" for text and flags.
HEADER = {
    "schema_version": ("-", "the message schema's version (messages.SCHEMA_VERSION)"),
    "step": ("-", "the lock-step index the content is valid at"),
    "t": ("s", "simulated time, step x dt"),
    "source": ("", "the app instance that published it (`operator` for a person's override)"),
}

FIELDS: dict[str, dict[str, tuple[str, str]]] = {
    "State": {
        "u": ("m/s", "surge, through the water, body x"),
        "v": ("m/s", "sway, through the water, body y"),
        "r": ("rad/s", "yaw rate, psi'"),
        "x": ("m", "position, submarine frame: forward along its axis from its CB"),
        "y": ("m", "position, submarine frame: lateral"),
        "psi": ("rad", "heading, submarine frame: from +x towards +y"),
    },
    "Desired": {
        "u_d": ("m/s", "desired surge speed"),
        "psi_d": ("rad", "desired heading, submarine frame: from +x towards +y"),
    },
    "Input": {
        "X_prop": ("N", "propeller thrust, body x"),
        "delta_r": ("rad", "rudder angle (the sim saturates it at the vehicle's limit)"),
    },
    "HelmProgress": {
        "behaviour": ("", "the behaviour in charge"),
        "leg": ("-", "the leg index"),
        "waypoint_index": ("-", "the current waypoint's index"),
        "waypoints_reached": ("-", "waypoints reached so far"),
        "psi_d": ("rad", "the desired heading the helm chose, submarine frame"),
        "delta_psi": ("rad", "the N_uv compensation's heading offset used (after the tip guard)"),
        "cross_track": ("m", "distance to the current track-line"),
        "n_s": ("N m", "interaction yaw moment used by N_uv compensation"),
        "complete": ("", "the helm's mission is complete"),
        "mode": ("", "the helm's MODE variable (hierarchical, ':' separated)"),
        "active": ("", "behaviours with an objective, by priority"),
        "winner": ("", "the behaviour whose own decision was taken, if any"),
        "delta_psi_commanded": ("rad", "the N_uv compensation's offset (thesis 6.1) before the guard"),
        "guard_active": ("", "the tip-clearance guard is active"),
        "guard_saturated": ("", "the guard's limit or rate limit cut the command"),
        "guard_limit": ("rad", "largest offset keeping the tip guard_clearance off the hull (signed)"),
        "guard_clearance": ("m", "the tip clearance the guard keeps"),
    },
    "Forces": {
        "X_s": ("N", "interaction force before the weight, body x"),
        "Y_s": ("N", "interaction force before the weight, body y"),
        "N_s": ("N m", "interaction yaw moment before the weight, about the UUV's CB"),
        "std_X": ("N", "the model's std of X (NaN where not asked)"),
        "std_Y": ("N", "the model's std of Y (NaN where not asked)"),
        "std_N": ("N m", "the model's std of N (NaN where not asked)"),
        "weight": ("-", "the blend weight of the interaction (0 outside the surrogate's domain)"),
        "in_domain": ("", "the state is inside table 4.2's box"),
        "constraints_ok": ("", "the state meets constraints (4.4)-(4.7)"),
        "applied_X": ("N", "weight x X_s: what the dynamics used, body x"),
        "applied_Y": ("N", "weight x Y_s: what the dynamics used, body y"),
        "applied_N": ("N m", "weight x N_s: what the dynamics used"),
        "model_X": ("N", "the model's raw answer, body x (NaN where not asked)"),
        "model_Y": ("N", "the model's raw answer, body y (NaN where not asked)"),
        "model_N": ("N m", "the model's raw answer, yaw (NaN where not asked)"),
        "lf_X": ("N", "the LF increment LF - LF_free, body x (NaN when unused)"),
        "lf_Y": ("N", "the LF increment LF - LF_free, body y (NaN when unused)"),
        "lf_N": ("N m", "the LF increment LF - LF_free, yaw (NaN when unused)"),
        "delta_weight": ("-", "the weight of the discrepancy delta (NaN when unused)"),
        "outside": ("", "the inputs and constraints the state is outside of"),
        "lf_held": ("", "the LF held its field at 1 cm from the submarine's widest radius"),
        "viscous_X": ("N", "the viscous correction's part of X_s, body x (0 without one)"),
        "viscous_Y": ("N", "the viscous correction's part of Y_s, body y (0 without one)"),
        "viscous_N": ("N m", "the viscous correction's part of N_s, yaw (0 without one)"),
    },
    "Poke": {"values": ("", "mission variables for the helm: name -> text, number or flag")},
    "Tick": {},
    "Ack": {
        "end": ("", "asks the clock to end the mission after this step with this outcome"),
        "reason": ("", "why, for people"),
    },
    "MissionEnd": {"outcome": ("", "how the mission ended"), "reason": ("", "why, for people")},
    "Event": {
        "kind": ("", "waypoint, collision, close_call, large_stray, saturation, app_joined, ..."),
        "detail": ("", "one line for people"),
        "data": ("", "the event's values, by name"),
    },
    "Control": {
        "cmd": ("", "pause, resume, status, warp, handover, retire, ..."),
        "args": ("", "the request's arguments"),
        "request_id": ("", "matches the reply"),
        "reply_to": ("", "who gets the reply (nearsub/<mission>/reply/<name>)"),
    },
    "ControlReply": {
        "request_id": ("", "the request's"),
        "ok": ("", "the request was carried out"),
        "data": ("", "the answer"),
        "error": ("", "why not, for people"),
    },
    "AppStatus": {
        "app": ("", "the app's role"),
        "instance": ("", "the app instance"),
        "state": ("", "starting, running or stopping"),
    },
}

# A raw angle unit -> (the suffix of its field for people, the unit people read).
FOR_PEOPLE = {"rad": ("_deg", "deg"), "rad/s": ("_deg_s", "deg/s")}
PEOPLE_DIGITS = 3  # degrees to a thousandth: below any heading a person reads or a helm resolves


def people_name(model: str, field: str) -> str:
    """The name people read a raw field by: NAME_deg for an angle, else the name itself."""
    unit = FIELDS.get(model, {}).get(field, ("",))[0]
    return field + FOR_PEOPLE[unit][0] if unit in FOR_PEOPLE else field


def people_unit(model: str, field: str) -> str | None:
    """The unit people read an angle field in (deg, deg/s); None for a field shown as it is."""
    unit = FIELDS.get(model, {}).get(field, ("",))[0]
    return FOR_PEOPLE[unit][1] if unit in FOR_PEOPLE else None


def for_people(model: str, fields: dict) -> dict:
    """A message's fields as people read them: each angle in degrees under NAME_deg, the rest as is."""
    shown = {}
    for name, value in fields.items():
        shown_name = people_name(model, name)
        if shown_name != name and isinstance(value, int | float) and not isinstance(value, bool):
            value = round(math.degrees(value), PEOPLE_DIGITS) if math.isfinite(value) else value
        shown[shown_name] = value
    return shown


def from_people(model: str, fields: dict) -> dict:
    """Fields as a person typed them back to the raw ones: NAME_deg (in degrees) to NAME in
    radians. ValueError naming a field given both ways, or a NAME_deg that is not a number."""
    raw = dict(fields)
    for name in FIELDS.get(model, {}):
        shown = people_name(model, name)
        if shown == name or shown not in raw:
            continue
        value = raw.pop(shown)
        if name in raw:
            raise ValueError(f"{name} and {shown} both given: give one")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{shown} = {value!r}: not a number of degrees")
        raw[name] = math.radians(value)
    return raw


def markdown_tables() -> str:
    """docs/messages.md's tables: the header, then each message's own fields."""
    lines = ["### Every message's header", "", *_table(None, HEADER)]
    for model, fields in FIELDS.items():
        lines += ["", f"### {model}", ""]
        lines += _table(model, fields) if fields else ["No fields beyond the header."]
    return "\n".join(lines) + "\n"


def _table(model: str | None, fields: dict) -> list[str]:
    rows = ["| field | unit | what, and in which frame | people read/type |", "|---|---|---|---|"]
    for name, (unit, meaning) in fields.items():
        shown = people_name(model, name) if model else name
        people = f"`{shown}` [{FOR_PEOPLE[unit][1]}]" if shown != name else "as is"
        rows.append(f"| `{name}` | {unit or ' '} | {meaning} | {people} |")
    return rows
