"""`nearsub swap MISSION APP --with SETTINGS`: replace a running app without stopping the mission.

SETTINGS is a comma-separated list of settings of the new app, e.g. `behaviour=waypoints,period=5`;
keys are relative to the app's mission section (`apps.helm`) unless they start with `apps.`.
The launcher pauses the clock at the next step boundary (or at `--at-step N`), starts the new
instance, which takes over the old one's progress (the current waypoint) and inputs, retires the
old one and resumes.
"""

from __future__ import annotations

import argparse
import json
import sys

from ..support.arguments import STEP, number
from ..support.connect import add_connect_arguments, open_bus


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("swap")
    add_connect_arguments(p)
    p.add_argument("app", help="role to replace, e.g. helm")
    p.add_argument(
        "--with",
        dest="with_",
        type=settings_list,
        default=[],
        metavar="SETTINGS",
        help="settings of the new app: key=value,key=value",
    )
    p.add_argument("--behaviour", help="shorthand for --with behaviour=NAME")
    p.add_argument("--vehicle", help="the vehicle whose app to replace (needed when the mission has several)")
    p.add_argument("--at-step", type=STEP, help="swap when the clock reaches this step (default: now)")
    p.add_argument("--timeout", type=number(above=0.0), default=120.0, help="wall seconds to wait for the swap")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=swap_command)


def settings_list(spec: str) -> list[str]:
    """'a=1,b=2' -> ['a=1', 'b=2'], for argparse."""
    items = [item.strip() for item in spec.split(",") if item.strip()]
    for item in items:
        if "=" not in item:
            raise argparse.ArgumentTypeError(f"item {item!r} is not key=value")
    return items


def vehicle_problem(args, community: str) -> str | None:
    """What is wrong with --vehicle for the mission as the registry knows it (None: fine, or a
    mission reached with --connect, which the launcher checks itself)."""
    if args.connect:
        return None
    from ..support import registry

    vehicles = registry.lookup(community).get("vehicles", [])
    if args.vehicle is None and len(vehicles) > 1:
        return f"mission {community!r} has several vehicles ({', '.join(vehicles)}): name one"
    if args.vehicle is not None and args.vehicle not in vehicles:
        known = ", ".join(vehicles) or "none: it has no [[vehicles]]"
        return f"no vehicle named {args.vehicle!r} in mission {community!r} (its vehicles: {known})"
    return None


def swap_command(args) -> int:
    overrides = list(args.with_)
    if args.behaviour:
        overrides.append(f"behaviour={args.behaviour}")
    bus, community = open_bus(args)  # no such mission: the command line reports it, exit 2
    if problem := vehicle_problem(args, community):
        print(f"nearsub swap: --vehicle: {problem}", file=sys.stderr)
        return 2
    import msgpack

    from nearsub.common.runtime import keys

    request = {"cmd": "swap", "app": args.app, "set": overrides, "at_step": args.at_step, "vehicle": args.vehicle}
    request = msgpack.packb(request)
    with bus:
        replies = bus.request(keys.launcher_control(community), request, timeout=args.timeout)
    if not replies:
        print(f"nearsub swap: the launcher of {community!r} did not answer", file=sys.stderr)
        return 1
    ok, payload = replies[0]
    if not ok and payload == b"Timeout":  # Zenoh's own error reply when --timeout passes
        print(
            f"nearsub swap: the launcher of {community!r} did not finish the swap within --timeout {args.timeout:g} s "
            f"(it goes on; `nearsub clock {community} status` shows whether the clock resumed)",
            file=sys.stderr,
        )
        return 1
    if not ok:
        print(f"nearsub swap: {payload.decode(errors='replace')}", file=sys.stderr)
        return 1
    result = msgpack.unpackb(payload)
    if "refused" in result:  # the request itself is wrong (the app, the vehicle, a setting)
        print(f"nearsub swap: {result['refused']}", file=sys.stderr)
        return 2
    print(json.dumps(result) if args.json else f"swapped {result['old']} -> {result['new']} at step {result['step']}")
    return 0
