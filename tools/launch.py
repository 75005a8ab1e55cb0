"""`nearsub launch MISSION`: run a mission file as separate processes, supervised by `launcher`."""

from __future__ import annotations

import json
import sys

from . import registry


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("launch")
    p.add_argument("mission", help="mission file (TOML)")
    p.add_argument("--warp", type=float, help="time warp: 0 = as fast as possible, 1 = real time")
    p.add_argument("--until", type=float, metavar="T", help="stop after T simulated seconds")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a mission setting")
    p.add_argument("--log", default="logs", metavar="DIR", help="folder for logs (default: logs)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=launch_command)


def launch_command(args) -> int:
    from nearsub.common.mission.schema import MissionError, load_mission

    from .launcher import Launcher, exit_code

    overrides = list(args.set)
    if args.warp is not None:
        overrides.append(f"warp={args.warp}")
    if args.until is not None:
        overrides.append(f"time_limit={args.until}")
    try:
        mission = load_mission(args.mission, overrides)
    except MissionError as exc:
        print(f"nearsub launch: {exc}", file=sys.stderr)
        return 2
    if mission.name in registry.running():
        print(
            f"nearsub launch: a mission named {mission.name!r} is already running; use --set name=OTHER",
            file=sys.stderr,
        )
        return 2
    summary = Launcher(mission, args.mission, args.log, quiet=args.json).run()
    print(json.dumps(summary.as_dict()) if args.json else summary.text())
    return exit_code(summary)
