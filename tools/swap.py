"""`nearsub swap COMMUNITY APP --with SPEC`: replace a running app without stopping the mission.

SPEC is a comma-separated list of settings of the new app, e.g. `behaviour=waypoints,period=5`;
keys are relative to the app's mission section (`apps.helm`) unless they start with `apps.`.
The launcher pauses the clock at the next step boundary (or at `--at-step N`), starts the new
instance, which takes over the old one's progress (the current waypoint) and inputs, retires the
old one and resumes.
"""

from __future__ import annotations

import json
import sys
import uuid

import msgpack

from nearsub.common.runtime import keys

from .connect import Caller, open_bus


def parse_spec(spec: str | None) -> list[str]:
    if not spec:
        return []
    items = [item.strip() for item in spec.split(",") if item.strip()]
    for item in items:
        if "=" not in item:
            raise ValueError(f"--with item {item!r} is not key=value")
    return items


def swap_command(args) -> int:
    try:
        overrides = parse_spec(args.with_)
    except ValueError as exc:
        print(f"nearsub swap: {exc}", file=sys.stderr)
        return 2
    if args.behaviour:
        overrides.append(f"behaviour={args.behaviour}")
    try:
        bus, community = open_bus(args)
    except LookupError as exc:
        print(f"nearsub swap: {exc}", file=sys.stderr)
        return 2
    request = msgpack.packb({"cmd": "swap", "app": args.app, "set": overrides, "at_step": args.at_step})
    with bus:
        replies = bus.request(keys.launcher_control(community), request, timeout=args.timeout)
    if not replies:
        print(f"nearsub swap: the launcher of {community!r} did not answer", file=sys.stderr)
        return 1
    ok, payload = replies[0]
    if not ok:
        print(f"nearsub swap: {payload.decode(errors='replace')}", file=sys.stderr)
        return 1
    result = msgpack.unpackb(payload)
    print(json.dumps(result) if args.json else f"swapped {result['old']} -> {result['new']} at step {result['step']}")
    return 0


def clock_command(args) -> int:
    """`nearsub clock COMMUNITY status|pause|resume`."""
    try:
        bus, community = open_bus(args)
    except LookupError as exc:
        print(f"nearsub clock: {exc}", file=sys.stderr)
        return 2
    extra = {"at": args.at_step} if args.action == "pause" and args.at_step is not None else {}
    with bus:
        caller = Caller(bus, community, f"tool-{uuid.uuid4().hex[:8]}")
        reply = caller.call("clock", args.action, timeout=600.0 if extra else 10.0, **extra)
    if reply is None:
        print(f"nearsub clock: the clock of {community!r} did not answer", file=sys.stderr)
        return 1
    if not reply.ok:
        print(f"nearsub clock: {reply.error}", file=sys.stderr)
        return 1
    print(json.dumps(reply.data))
    return 0
