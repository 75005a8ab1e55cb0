"""`nearsub clock COMMUNITY status|pause|resume`: ask a running mission's clock."""

from __future__ import annotations

import json
import sys
import uuid

from .connect import add_router_argument, open_bus


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("clock")
    p.add_argument("community", help="mission name")
    p.add_argument("action", choices=("status", "pause", "resume"))
    p.add_argument("--at-step", type=int, help="with pause: pause when the clock reaches this step")
    add_router_argument(p)
    p.set_defaults(func=clock_command)


def clock_command(args) -> int:
    bus, community = open_bus(args)  # no such mission: the command line reports it, exit 2
    from .caller import Caller

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
