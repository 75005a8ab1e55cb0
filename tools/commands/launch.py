"""`nearsub launch MISSION`: run a mission file as separate processes, supervised by the `launcher` package."""

from __future__ import annotations

import json
import sys
import zipfile
from pathlib import Path

from ..support import registry
from ..support.arguments import number
from ..support.errors import InputError
from ..support.missions import add_shipped_completion
from .view import PORT


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("launch")
    add_shipped_completion(
        p.add_argument("mission", help="mission file (TOML), or a shipped mission's name (alpha: missions/alpha.toml)")
    )
    p.add_argument("--warp", type=number(minimum=0.0), help="time warp: 0 = as fast as possible, 1 = real time")
    p.add_argument("--until", type=number(above=0.0), metavar="T", help="stop after T simulated seconds")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a mission setting")
    p.add_argument("--log", default="logs", metavar="DIR", help="folder for logs (default: logs)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--view", action="store_true", help="also serve the live map in the browser (nearsub view)")
    p.add_argument("--view-port", type=PORT, metavar="N", help="its port on 127.0.0.1 (default: a free one)")
    p.add_argument("--foxglove", action="store_true", help="also serve the mission to Foxglove (nearsub foxglove)")
    p.add_argument("--foxglove-port", type=PORT, metavar="N", help="its port on 127.0.0.1 (default: a free one)")
    p.add_argument(
        "--vehicles",
        metavar="NAME,...",
        help="a fleet over several hosts: start only these vehicles' apps here (the others join from "
        "another host; needs network.connect)",
    )
    p.add_argument(
        "--join",
        action="store_true",
        help="with --vehicles: join the mission launched on another host (these vehicles' apps only: "
        "no logger, clock or surrogate server)",
    )
    p.set_defaults(func=launch_command)


def companions(args) -> list:
    """The servers `--view` and `--foxglove` ask for: each starts from the launcher's run file, with
    the apps' environment, once the apps are up, and prints where it listens. A port without its server is refused
    rather than ignored: the user surely wanted the server."""
    servers = {"view": (args.view, args.view_port), "foxglove": (args.foxglove, args.foxglove_port)}
    wanted = []
    for tool, (on, port) in servers.items():
        if port is not None and not on:
            raise InputError(f"--{tool}-port {port}: add --{tool}, which serves on it")
        if on:
            wanted.append((tool, port or 0))  # 0: a free port, printed

    def starter(tool: str, port: int):
        def start(run_file, env):
            from ..launcher.processes import LaunchError
            from .view import start_server_process

            try:
                process, url = start_server_process(tool, run_file, port, env=env)
            except RuntimeError as exc:
                raise LaunchError(str(exc), app=tool) from None
            print(f"nearsub launch: {tool} at {url}", file=sys.stderr, flush=True)
            return process

        return start

    return [starter(tool, port) for tool, port in wanted]


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


ROOM_SECONDS = 60.0  # simulated seconds of log a launch wants room for before it starts


def check_room(folder: str, mission) -> None:
    """Refuse a log folder without room for the mission's first ROOM_SECONDS (a full disk would
    otherwise stop the mission a few steps in, or its router before it listens)."""
    import shutil

    from nearsub.common.runtime.logfile import room_needed

    steps = min(mission.max_steps, round(ROOM_SECONDS / mission.dt))
    needed, free = room_needed(steps, len(mission.vehicle_names)), shutil.disk_usage(folder).free
    if free < needed:
        raise InputError(
            f"--log {folder}: no space left on it for the mission's first {steps * mission.dt:g} s "
            f"({free // 1024} kB free, about {needed // 1024} kB needed)"
        )


def vehicles_here(args, mission) -> list[str] | None:
    """The vehicles whose apps this launch starts (`--vehicles`; None: all), checked against the
    mission: a fleet, names it has, and a router the other hosts can reach."""
    if args.vehicles is None:
        if args.join:
            raise InputError("--join: name the vehicles whose apps run on this host with --vehicles")
        return None
    names = [name.strip() for name in args.vehicles.split(",")]
    if not mission.fleet:
        raise InputError(
            f"--vehicles {args.vehicles}: mission {mission.name!r} has no [[vehicles]]: one launch runs it"
        )
    known = mission.vehicle_names
    for name in names:
        if name not in known:
            raise InputError(f"--vehicles {name}: no vehicle named {name!r} ({', '.join(known)})")
        if names.count(name) > 1:
            raise InputError(f"--vehicles {args.vehicles}: {name} is named twice")
    if not mission.network.connect:
        raise InputError(
            f"--vehicles {args.vehicles}: the other vehicles' apps join from another host through the "
            'mission\'s router: set network.connect (docs/network.md, "A fleet over several hosts")'
        )
    return names


def launch_command(args) -> int:
    from ..launcher.status import Summary, exit_code, interrupted_reason

    try:
        return _launch(args)
    except KeyboardInterrupt:  # before the launcher takes Ctrl-C over (reading the mission, importing)
        summary = Summary(Path(args.mission).stem, "interrupted")
        summary.reason = interrupted_reason(summary)
        print(json.dumps(summary.as_dict()) if args.json else summary.text())
        return exit_code(summary)


def _launch(args) -> int:
    from nearsub.common.mission.schema import MissionError, load_mission, mission_path

    from ..launcher.status import exit_code
    from ..launcher.supervision import Launcher

    extra = companions(args)
    overrides = list(args.set)
    typed = {}  # the override each option stands for -> the option as typed, for the error lines
    for option, key, value in (("--warp", "warp", args.warp), ("--until", "time_limit", args.until)):
        if value is not None:
            overrides.append(f"{key}={value}")
            typed[f"--set {key}={value}:"] = f"{option} {value:g}:"
    try:
        args.mission = str(mission_path(args.mission))  # a shipped mission by name: its file
        mission = load_mission(args.mission, overrides)
    except MissionError as exc:
        text = str(exc)
        given = next((g for g in typed if text.startswith(g)), None)
        print(f"nearsub launch: {text if given is None else typed[given] + text[len(given) :]}", file=sys.stderr)
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
    here = vehicles_here(args, mission)
    try:  # here, after every other check, so that a file in the way is named as the option
        Path(args.log).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--log {args.log}: cannot make a folder there ({exc.strerror})") from None
    if args.join:  # no log, no claim: the mission's own launch holds both
        summary = Launcher(mission, args.mission, args.log, args.json, extra, here, join=True).run()
        print(json.dumps(summary.as_dict()) if args.json else summary.text())
        return exit_code(summary)
    check_room(args.log, mission)
    # The claim is held until this process exits; a second launch of the name refuses at once.
    try:
        with registry.claim(mission.name):
            summary = Launcher(mission, args.mission, args.log, quiet=args.json, companions=extra, here=here).run()
    except registry.NameTaken as exc:
        print(f"nearsub launch: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(summary.as_dict()) if args.json else summary.text())
    return exit_code(summary)
