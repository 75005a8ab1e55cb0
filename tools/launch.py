"""`nearsub launch MISSION`: run a mission file as separate processes, supervised by `launcher`."""

from __future__ import annotations

import ipaddress
import json
import sys
import zipfile
from pathlib import Path

from . import registry


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("launch")
    p.add_argument("mission", help="mission file (TOML)")
    p.add_argument("--warp", type=float, help="time warp: 0 = as fast as possible, 1 = real time")
    p.add_argument("--until", type=float, metavar="T", help="stop after T simulated seconds")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a mission setting")
    p.add_argument("--log", default="logs", metavar="DIR", help="folder for logs (default: logs)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--view", action="store_true", help="also serve the live map in the browser (nearsub view)")
    p.add_argument("--view-port", type=int, default=0, metavar="N", help="its port on 127.0.0.1 (default: a free one)")
    p.add_argument("--foxglove", action="store_true", help="also serve the mission to Foxglove (nearsub foxglove)")
    p.add_argument("--foxglove-port", type=int, default=8765, metavar="N", help="its port on 127.0.0.1 (default 8765)")
    p.set_defaults(func=launch_command)


def companions(args) -> list:
    """The servers `--view` and `--foxglove` ask for: each starts from the launcher's run file
    once the apps are up, and prints where it listens."""
    from .view import check_port

    wanted = [(tool, port) for tool, on, port in (("view", args.view, args.view_port),
              ("foxglove", args.foxglove, args.foxglove_port)) if on]  # fmt: skip
    for _, port in wanted:
        check_port(port)

    def starter(tool: str, port: int):
        def start(run_file):
            from .launcher import LaunchError
            from .view import start_server_process

            try:
                process, url = start_server_process(tool, run_file, port)
            except RuntimeError as exc:
                raise LaunchError(str(exc), app=tool) from None
            print(f"nearsub launch: {tool} at {url}", file=sys.stderr, flush=True)
            return process

        return start

    return [starter(tool, port) for tool, port in wanted]


def endpoint_problem(endpoint: str) -> str | None:
    """Why a `network.connect` endpoint that has the shape of one cannot be an address: a host
    written as an IP address that is not one (tcp/256.1.1.1:7447, tcp/[::g]:7447). Host names are
    left to the resolver: one that does not resolve is reported as unreachable."""
    protocol, _, address = endpoint.partition("/")
    if protocol == "unixsock-stream":
        return None
    host = address.rsplit(":", 1)[0]
    literal = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if host.startswith("[") or literal.replace(".", "").isdigit():
        try:
            ipaddress.ip_address(literal)
        except ValueError:
            return f"network.connect: {endpoint!r}: {literal!r} is not an IP address"
    return None


def model_file_problem(path: str) -> str | None:
    """Why the mission's surrogate model file cannot be a model file, checked before any app
    starts (a mistyped path otherwise surfaced seconds later as the server's failed start-up);
    the server reads it whole and names any deeper problem."""
    file = Path(path)
    if not file.is_file():
        return "no such file"
    if not zipfile.is_zipfile(file):
        return "not a nearsub model file (not an .npz archive)"
    return None


def launch_command(args) -> int:
    from nearsub.common.mission.schema import MissionError, load_mission

    from .launcher import Launcher, exit_code

    extra = companions(args)
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
    for endpoint in mission.network.connect:
        if problem := endpoint_problem(endpoint):
            print(f"nearsub launch: {problem}", file=sys.stderr)
            return 2
    if mission.network.credentials:
        from nearsub.common.runtime.credentials import CredentialsError, load

        try:
            load(mission.network.credentials)
        except CredentialsError as exc:
            print(f"nearsub launch: network.credentials: {exc}", file=sys.stderr)
            return 2
    if mission.needs_surrogate and mission.surrogate.model:
        if problem := model_file_problem(mission.surrogate.model):
            print(f"nearsub launch: surrogate.model = {mission.surrogate.model!r}: {problem}", file=sys.stderr)
            return 2
    # The claim is held until this process exits; a second launch of the name refuses at once.
    try:
        with registry.claim(mission.name):
            summary = Launcher(mission, args.mission, args.log, quiet=args.json, companions=extra).run()
    except registry.NameTaken as exc:
        print(f"nearsub launch: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(summary.as_dict()) if args.json else summary.text())
    return exit_code(summary)
