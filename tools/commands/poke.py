"""`nearsub poke MISSION NAME=VALUE ...`: set mission variables in a running helm (uPokeDB).

The poke travels as an operator override (`nearsub tap pub` on the vehicle's `poke` topic): the
helm applies it at the next step it runs, records that step in an info event, which this command
waits for and prints, and the log replays it (docs/design.md, "The helm")."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

from ..support.connect import add_router_argument


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("poke", help="set mission variables of a running helm (uPokeDB)")
    p.add_argument("mission", help="the mission file, or the running mission's (community) name with --vehicle")
    p.add_argument("assignments", nargs="+", metavar="NAME=VALUE", help="values are read as TOML, else as text")
    p.add_argument("--vehicle", help="the vehicle's name in the keys (default: the mission file's single vehicle)")
    add_router_argument(p)
    p.set_defaults(func=run)


def parse_assignments(texts: list[str]) -> dict:
    """NAME=VALUE pairs; ValueError naming the bad one."""
    from nearsub.common.mission.schema import VARIABLE_PATTERN, parse_override

    values = {}
    for text in texts:
        if "=" not in text:
            raise ValueError(f"{text!r}: expected NAME=VALUE")
        name = text.split("=", 1)[0].strip()
        if not VARIABLE_PATTERN.match(name):
            raise ValueError(f"{text!r}: variable name {name!r} is not letters, digits and '_'")
        _, value = parse_override(text)
        if not isinstance(value, str | int | float | bool):
            raise ValueError(f"{text!r}: value {value!r} is not a string, number or boolean")
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"{text!r}: {value} is not a finite number")
        values[name] = float(value) if isinstance(value, int) and not isinstance(value, bool) else value
    return values


def run(args) -> int:
    from nearsub.common.mission.schema import MissionError, load_mission

    from . import tap

    try:
        values = parse_assignments(args.assignments)
    except ValueError as exc:
        print(f"nearsub poke: {exc}", file=sys.stderr)
        return 2
    community, vehicle = args.mission, args.vehicle
    if Path(args.mission).suffix == ".toml":
        try:
            mission = load_mission(args.mission)
        except MissionError as exc:
            print(f"nearsub poke: {exc}", file=sys.stderr)
            return 2
        fleet = [entry["name"] for entry in mission.model_dump().get("vehicles") or []]
        vehicle = fleet[0] if vehicle is None and len(fleet) == 1 else vehicle
        if fleet and vehicle not in fleet:  # several vehicles: the poke names whose helm it sets
            given = f"--vehicle {vehicle}: not a vehicle of {args.mission}" if vehicle else "give --vehicle NAME"
            print(f"nearsub poke: {given} (its vehicles: {', '.join(fleet)})", file=sys.stderr)
            return 2
        community, vehicle = mission.name, vehicle or mission.vehicle_name
    if vehicle is None:
        print(f"nearsub poke: give --vehicle for the running mission {community!r}, or its file", file=sys.stderr)
        return 2
    pub = type(args)(
        key=f"nearsub/{community}/{vehicle}/poke",
        value=json.dumps({"values": values}),
        raw_hex=None,
        no_validate=False,
        connect=args.connect,
        credentials=args.credentials,
        community=community,
    )
    return tap.tap_pub(pub)
