"""`nearsub poke MISSION [--vehicle NAME] NAME=VALUE ...`: set mission variables in a running helm (uPokeDB).

The poke travels as an operator override (`nearsub tap pub` on the vehicle's `poke` topic): the
helm applies it at the next step it runs, records that step in an info event, which this command
waits for and prints, and the log replays it (docs/design.md, "The helm")."""

from __future__ import annotations

import json
import math
import sys

from ..support.connect import add_connect_arguments


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("poke", help="set mission variables of a running helm (uPokeDB)")
    add_connect_arguments(p)
    p.add_argument("assignments", nargs="+", metavar="NAME=VALUE", help="values are read as TOML, else as text")
    p.add_argument("--vehicle", help="whose helm to poke (default: the mission's only vehicle)")
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
    from ..support.missions import mission_of
    from . import tap

    try:
        values = parse_assignments(args.assignments)
    except ValueError as exc:
        print(f"nearsub poke: {exc}", file=sys.stderr)
        return 2
    mission = mission_of(args)  # a name that is not running: the command line reports it, exit 2
    community, vehicle = args.mission if mission is None else mission.name, args.vehicle
    if mission is not None:
        fleet = [entry["name"] for entry in mission.model_dump().get("vehicles") or []]
        vehicle = fleet[0] if vehicle is None and len(fleet) == 1 else vehicle
        if fleet and vehicle not in fleet:  # several vehicles: the poke names whose helm it sets
            given = f"--vehicle {vehicle}: not a vehicle of {args.mission}" if vehicle else "give --vehicle NAME"
            print(f"nearsub poke: {given} (its vehicles: {', '.join(fleet)})", file=sys.stderr)
            return 2
        vehicle = vehicle or mission.vehicle_name
    if vehicle is None:
        print(f"nearsub poke: give --vehicle for the mission {community!r} reached with --connect", file=sys.stderr)
        return 2
    pub = type(args)(
        mission=community,
        key=f"nearsub/{community}/{vehicle}/poke",
        value=json.dumps({"values": values}),
        raw_hex=None,
        no_validate=False,
        connect=args.connect,
        credentials=args.credentials,
    )
    return tap.tap_pub(pub)
