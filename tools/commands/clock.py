"""`nearsub clock MISSION status|pause|resume|warp N`: ask a running mission's clock."""

from __future__ import annotations

import json
import sys
import uuid

from ..support.arguments import STEP
from ..support.connect import add_connect_arguments, open_bus


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("clock")
    add_connect_arguments(p)
    p.add_argument("action", choices=("status", "pause", "resume", "warp"))
    p.add_argument("warp", nargs="?", type=float, help="with warp: simulated seconds per wall second (0: flat out)")
    p.add_argument("--at-step", type=STEP, help="with pause: pause when the clock reaches this step")
    p.add_argument("--json", action="store_true", help="the reply as JSON (the default when piped)")
    p.set_defaults(func=clock_command)


def status_line(data: dict) -> str:
    """The compact status of a clock on a terminal: t, step, warp requested and achieved."""
    achieved = data.get("achieved_warp")
    warp = data.get("warp")
    requested = "flat out" if warp == 0 else f"{warp:g}x"
    measured = "not measured yet" if achieved is None else f"{achieved:.1f}x achieved"
    paused = "  paused" if data.get("paused") else ""
    return f"t={data.get('t', 0.0):.2f} s  step {data.get('step')}  warp {requested} requested, {measured}{paused}"


def clock_command(args) -> int:
    from nearsub.common.runtime.clock import MAX_WARP

    if args.action == "warp" and (args.warp is None or not 0 <= args.warp <= MAX_WARP):
        print(
            f"nearsub clock: warp needs a number from 0 to {MAX_WARP:g}, e.g. `nearsub clock alpha warp 20`",
            file=sys.stderr,
        )
        return 2
    if args.action != "warp" and args.warp is not None:
        print(f"nearsub clock: {args.action} takes no value", file=sys.stderr)
        return 2
    bus, community = open_bus(args)  # no such mission: the command line reports it, exit 2
    from ..support.caller import Caller

    extra = {"at": args.at_step} if args.action == "pause" and args.at_step is not None else {}
    if args.action == "warp":
        extra = {"warp": args.warp}
    with bus:
        caller = Caller(bus, community, f"tool-{uuid.uuid4().hex[:8]}")
        reply = caller.call("clock", args.action, timeout=600.0 if "at" in extra else 10.0, **extra)
    if reply is None:
        print(f"nearsub clock: the clock of {community!r} did not answer", file=sys.stderr)
        return 1
    if not reply.ok:
        print(f"nearsub clock: {reply.error}", file=sys.stderr)
        return 1
    if args.action in ("status", "warp") and not args.json and sys.stdout.isatty():
        print(status_line(reply.data))
    else:
        print(json.dumps(reply.data))
    return 0
