"""A mission's messages as Foxglove channels, all JSON: for `nearsub log export --format foxglove`
and the live server of `nearsub foxglove` (tools/commands/foxglove.py moves the bytes through foxglove-sdk).

Every nearsub topic keeps its key and its fields (simulated time `t` included) with the message
model's JSON schema; beside them, in Foxglove's own schemas:

- `/tf` (`foxglove.FrameTransform`): `world` -> `<vehicle>`, each UUV's pose in a frame named
  after it (the vehicle chunk of its keys);
- `/scene/mission` (`foxglove.SceneUpdate`): the submarine's outline to scale, the waypoints and
  track-lines, published once (and again by the live server for clients that join late);
- `/scene/uuv` (`foxglove.SceneUpdate`): each UUV to scale (outline and a cylinder of its length
  and diameter) in its own frame, so it follows `/tf`: one entity per vehicle, its id the
  vehicle's name, in its own colour and, with several vehicles, labelled with its name;
- `/events` (`foxglove.Log`): waypoints, collisions, close calls, swaps and the other events, the
  mission's and each vehicle's (named `<vehicle>/<source>`).

`world` is the mission's frame (docs/design.md, "Frames, units and signs"): x and y as in the
messages, z up, so psi (from +x towards +y) is a rotation about z. Foxglove's JSON form of its
schemas writes timestamps as {sec, nsec} and enums as integers; the JSON schemas are derived from
the protobuf descriptors foxglove-sdk ships, so they always match its message definitions.
"""

from __future__ import annotations

import json
import math
from functools import cache
from typing import Any

from nearsub.common.physics.hull import uuv_body_outline
from nearsub.common.runtime.keys import vehicle_of
from nearsub.common.runtime.messages import model_for_key

from .scene import static_scene, vehicle_size

WORLD = "world"
TF_TOPIC = "/tf"
MISSION_TOPIC = "/scene/mission"
UUV_TOPIC = "/scene/uuv"
EVENTS_TOPIC = "/events"
FOXGLOVE_TOPICS = {
    TF_TOPIC: "FrameTransform",
    MISSION_TOPIC: "SceneUpdate",
    UUV_TOPIC: "SceneUpdate",
    EVENTS_TOPIC: "Log",
}
LOG_LEVEL = {"collision": 4, "error": 4, "close_call": 3, "large_stray": 3, "saturation": 3}  # foxglove.Log.Level
INFO = 2
HULL_COLOUR = {"r": 0.55, "g": 0.6, "b": 0.65, "a": 1.0}
TRACK_COLOUR = {"r": 0.2, "g": 0.5, "b": 0.9, "a": 0.8}
UUV_COLOUR = {"r": 1.0, "g": 0.6, "b": 0.1, "a": 1.0}
OTHER_UUV_COLOURS = (  # the second and further vehicles, in name order
    {"r": 0.3, "g": 0.8, "b": 1.0, "a": 1.0},
    {"r": 0.4, "g": 1.0, "b": 0.55, "a": 1.0},
    {"r": 0.8, "g": 0.5, "b": 1.0, "a": 1.0},
)

# protobuf scalar field types (google/protobuf/descriptor.proto, FieldDescriptorProto.Type)
_PROTO_JSON = {1: "number", 2: "number", 3: "integer", 4: "integer", 5: "integer", 6: "integer", 7: "integer",
               8: "boolean", 9: "string", 12: "string", 13: "integer", 15: "integer", 16: "integer",
               17: "integer", 18: "integer"}  # fmt: skip
_MESSAGE, _ENUM, _REPEATED = 11, 14, 3


@cache
def foxglove_json_schema(name: str) -> dict:
    """The JSON schema of Foxglove's message `name` ("SceneUpdate"), from foxglove-sdk's protobuf
    descriptor of it, in Foxglove's JSON form (timestamps and durations as {sec, nsec})."""
    from foxglove import messages
    from google.protobuf import descriptor_pb2

    files = descriptor_pb2.FileDescriptorSet.FromString(getattr(messages, name).get_schema().data)
    types = {f".{f.package}.{m.name}": m for f in files.file for m in f.message_type}

    def schema_of(type_name: str) -> dict:
        if type_name in (".google.protobuf.Timestamp", ".google.protobuf.Duration"):
            return {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
        message = types[type_name]
        properties = {}
        for field in message.field:
            if field.type == _MESSAGE:
                item = schema_of(field.type_name)
            elif field.type == _ENUM:
                item = {"type": "integer"}
            else:
                item = {"type": _PROTO_JSON[field.type]}
            properties[field.name] = {"type": "array", "items": item} if field.label == _REPEATED else item
        return {"title": type_name[1:], "type": "object", "properties": properties}

    return schema_of(f".foxglove.{name}")


def schema_for(topic: str) -> tuple[str, dict]:
    """(schema name, JSON schema) of a channel: Foxglove's for its topics, the message model's
    for nearsub's keys, an open object for a key with no model."""
    if topic in FOXGLOVE_TOPICS:
        name = FOXGLOVE_TOPICS[topic]
        return f"foxglove.{name}", foxglove_json_schema(name)
    model = model_for_key(topic)
    if model is None:
        return "", {}
    return f"nearsub.{model.__name__}", model.model_json_schema()


def to_json(message: Any) -> bytes:
    """A message as JSON text; non-finite numbers (not JSON) become null."""
    try:
        return json.dumps(message, allow_nan=False).encode()
    except ValueError:
        return json.dumps(_finite(message), allow_nan=False).encode()


def _finite(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _point(x: float, y: float) -> dict:
    return {"x": float(x), "y": float(y), "z": 0.0}


def _pose(x: float, y: float, psi: float) -> dict:
    return {
        "position": _point(x, y),
        "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(psi / 2), "w": math.cos(psi / 2)},
    }


def _line(points, colour: dict, thickness: float, loop: bool = False) -> dict:
    return {
        "type": 1 if loop else 0,  # LINE_LOOP, LINE_STRIP (foxglove.LinePrimitive.Type)
        "pose": _pose(0.0, 0.0, 0.0),
        "thickness": thickness,
        "scale_invariant": False,
        "points": [_point(x, y) for x, y in points],
        "color": colour,
        "colors": [],
        "indices": [],
    }


class FoxgloveScene:
    """Turns a run's messages into Foxglove messages. `start_ns` is the epoch of simulated time 0:
    every message's log time and Foxglove timestamp is start_ns + its simulated time."""

    def __init__(self, mission, start_ns: int):
        self.start_ns = start_ns
        self.mission = mission
        self.scene = static_scene(mission)
        self.vehicle = self.scene["vehicle"]
        self.vehicles: list[str] = []
        self.sizes: dict[str, dict] = {}

    def log_time(self, sim_time: float) -> int:
        return self.start_ns + max(0, round(sim_time * 1e9))

    def mission_update(self, ns: int) -> dict:
        """The fixed part of the picture: hull outline, track-lines and waypoints."""
        lines = []
        if self.scene["hull"]:
            lines.append(_line(self.scene["hull"], HULL_COLOUR, 0.3, loop=True))
        for leg in self.scene["legs"]:
            lines.append(_line(leg["track"], TRACK_COLOUR, 0.15))
        entity = self._entity("mission", WORLD, ns, lines=lines)
        entity["spheres"] = [
            {"pose": _pose(x, y, 0.0), "size": {"x": 1.0, "y": 1.0, "z": 1.0}, "color": TRACK_COLOUR}
            for leg in self.scene["legs"]
            for x, y in leg["points"]
        ]
        return {"deletions": [], "entities": [entity]}

    def _entity(self, entity_id: str, frame: str, ns: int, **primitives) -> dict:
        entity = {
            "timestamp": stamp(ns),
            "frame_id": frame,
            "id": entity_id,
            "lifetime": {"sec": 0, "nsec": 0},  # until replaced
            "frame_locked": True,
            "metadata": [],
        }
        for kind in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
            entity[kind] = primitives.get(kind, [])
        return entity

    def translate(self, key: str, fields: dict, sim_time: float) -> list[tuple[str, dict, int]]:
        """(topic, message, log time in ns) for one nearsub message: itself, and for a state its
        transform and UUV entity, for an event its log line."""
        ns = self.log_time(sim_time)
        out = [(key, fields, ns)]
        parts = key.split("/")
        owner = vehicle_of(key)
        if owner is not None and owner[1] == "state" and len(parts) == 4:
            out += self._pose_messages(owner[0], fields, ns)
        elif len(parts) >= 4 and parts[2] == "events":
            kind = str(fields.get("kind", "info"))
            text = f"t={float(fields.get('t', sim_time)):.2f} s {kind}: {fields.get('detail', '')}"
            name = str(fields.get("source", parts[-1]))
            log = {"timestamp": stamp(ns), "level": LOG_LEVEL.get(kind, INFO), "message": text,
                   "name": name if owner is None else f"{owner[0]}/{name}", "file": key, "line": 0}  # fmt: skip
            out.append((EVENTS_TOPIC, log, ns))
        return out

    def _pose_messages(self, vehicle: str, state: dict, ns: int) -> list[tuple[str, dict, int]]:
        pose = _pose(float(state["x"]), float(state["y"]), float(state["psi"]))
        transform = {
            "timestamp": stamp(ns),
            "parent_frame_id": WORLD,
            "child_frame_id": vehicle,
            "translation": pose["position"],
            "rotation": pose["orientation"],
        }
        out = [(TF_TOPIC, transform, ns)]
        if vehicle not in self.vehicles:
            self.vehicles = sorted([*self.vehicles, vehicle])
            # A new vehicle can change the others' colours and labels: send them all again.
            out += [(UUV_TOPIC, self.uuv_update(v, ns), ns) for v in self.vehicles]
        return out

    def size(self, vehicle: str) -> dict:
        """Length and diameter of a vehicle: the mission's own, or its fleet entry's type."""
        if vehicle not in self.sizes:
            self.sizes[vehicle] = self.vehicle if self.mission is None else vehicle_size(self.mission, vehicle)
        return self.sizes[vehicle]

    def uuv_update(self, vehicle: str, ns: int) -> dict:
        """The UUV to scale in its own frame (locked to the frame `/tf` moves): outline and body,
        in its own colour, and its name above it when there are several."""
        length, diameter = self.size(vehicle)["length"], self.size(vehicle)["diameter"]
        index = self.vehicles.index(vehicle) if vehicle in self.vehicles else 0
        colour = UUV_COLOUR if index == 0 else OTHER_UUV_COLOURS[(index - 1) % len(OTHER_UUV_COLOURS)]
        bx, by = uuv_body_outline(length, diameter)
        body = {  # a cylinder's axis is its z: a quarter turn about y lays it along the UUV's x
            "pose": {
                "position": _point(0.0, 0.0),
                "orientation": {"x": 0.0, "y": math.sqrt(0.5), "z": 0.0, "w": math.sqrt(0.5)},
            },  # fmt: skip
            "size": {"x": diameter, "y": diameter, "z": length},
            "bottom_scale": 1.0,
            "top_scale": 1.0,
            "color": colour,
        }
        outline = _line(zip(bx, by, strict=True), colour, 0.05, loop=True)
        texts = []
        if len(self.vehicles) > 1:
            label = {
                "position": {"x": 0.0, "y": 0.0, "z": 2.0 * diameter},
                "orientation": _pose(0, 0, 0)["orientation"],
            }
            texts.append({"pose": label, "billboard": True, "font_size": 14.0, "scale_invariant": True,
                          "color": colour, "text": vehicle})  # fmt: skip
        entity = self._entity(vehicle, vehicle, ns, lines=[outline], cylinders=[body], texts=texts)
        return {"deletions": [], "entities": [entity]}

    def static_updates(self, sim_time: float) -> list[tuple[str, dict, int]]:
        """The mission and every UUV seen so far, stamped at `sim_time` (for late joiners)."""
        ns = self.log_time(sim_time)
        return [(MISSION_TOPIC, self.mission_update(ns), ns)] + [
            (UUV_TOPIC, self.uuv_update(v, ns), ns) for v in self.vehicles
        ]
