"""`nearsub view MISSION | LOG.mcap`: the live map in a browser (the pMarineViewer of nearsub).

With a mission (its name, tools/support/missions.py) it follows the running mission (found
through the launcher's registry, or `--connect ENDPOINT`); with a log file it replays the log
with a timeline to scrub. Either way it serves one page on http://127.0.0.1:PORT/?token=TOKEN (a
free port unless `--port` is given) and prints its URL, then the read-only one
(tools/view_server.py, "Access"). A running mission's tokens derive from its credentials, which
the registry names in the runtime folder only their owner can read. The mission (waypoints,
vehicle, submarine) comes from the launcher's run file, which the registry entry points to, or
from the log's metadata.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..support.arguments import integer
from ..support.errors import InputError
from ..support.log_input import check_log, is_log, mission_of_log
from ..support.missions import add_mission_argument, mission_name, mission_of_run

PORT = integer(minimum=0, maximum=65535)  # a TCP port; 0: a free one


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("view", help="live map of a running mission, or replay of a log, in a browser")
    add_mission_argument(p, or_log=True)
    p.add_argument("--port", type=PORT, default=0, help="TCP port on 127.0.0.1 (default: a free one)")
    p.add_argument("--connect", action="append", metavar="ENDPOINT", help="router endpoint instead of the registry")
    p.add_argument(
        "--run",
        metavar="RUN.json",
        help="the launcher's run file (mission, endpoints, log folder) instead of the registry",
    )
    p.set_defaults(func=view_command)


def start_viewer(run_file: str | Path, port: int = 0, timeout: float = 30.0):
    """Start `nearsub view` for the mission of a launcher's run file in its own process; returns
    (process, URL). For `nearsub launch --view`: call it once the apps are up, stop the process
    with the other children."""
    return start_server_process("view", run_file, port, timeout)


def start_server_process(tool: str, run_file: str | Path, port: int, timeout: float | None = None, env=None):
    """Start `nearsub TOOL MISSION --run RUN_FILE --port PORT` (view, foxglove) in its own process
    group with the environment `env` (default: this process's); returns (process, URL) once it
    prints `nearsub TOOL: URL` (within `timeout`, by default the mission's start-up timeout)."""
    import queue
    import subprocess
    import threading

    from nearsub.common.mission.schema import RunConfig

    mission = RunConfig.load(run_file).mission
    community, timeout = mission.name, mission.startup_timeout if timeout is None else timeout
    argv = [sys.executable, "-m", "nearsub", tool, community, "--run", str(run_file), "--port", str(port)]
    from nearsub.common.runtime.processes import parent_death_signal

    # It ends with the launcher however the launcher ends (SIGKILL included), as the apps do.
    process = subprocess.Popen(
        argv,
        stdout=subprocess.PIPE,
        text=True,
        stdin=subprocess.DEVNULL,
        process_group=0,
        env=env,
        preexec_fn=parent_death_signal(),
    )
    lines: queue.Queue = queue.Queue()
    # Every line, then None when its output closes (it exited: its stderr has said why).
    threading.Thread(target=lambda: [*map(lines.put, process.stdout), lines.put(None)], daemon=True).start()
    try:
        line = lines.get(timeout=timeout)
    except queue.Empty:
        process.kill()
        raise RuntimeError(f"nearsub {tool} did not start within {timeout:g} s") from None
    if line is None:
        raise RuntimeError(f"nearsub {tool} exited with code {process.wait()} before serving")
    prefix = f"nearsub {tool}: "
    if not (line.startswith(prefix + "http") or line.startswith(prefix + "ws")):
        process.kill()
        raise RuntimeError(line.strip())
    return process, line.split(": ", 1)[1].strip()


def view_command(args) -> int:
    if is_log(args.mission):
        path = Path(args.mission)
        check_log(path)
        return _replay(path, args.port)
    return _live(mission_name(args.mission), args.connect, args.run, args.port)


def _ready(url: str) -> None:
    print(f"nearsub view: {url}", flush=True)


def _serve(main, port: int) -> int:
    """Run the server coroutine until Ctrl-C; a port that cannot be bound is bad input."""
    import asyncio

    try:
        asyncio.run(main)
    except OSError as exc:
        print(f"nearsub view: cannot serve on 127.0.0.1:{port} ({exc.strerror})", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0
    return 0


def _replay(path: Path, port: int) -> int:
    from nearsub.common.mission.schema import MissionError

    from ..view_server import ReplaySource, ViewerAccess, serve_viewer

    try:
        mission = mission_of_log(path)
        source = ReplaySource(path, mission)
        if not source.model.poses:
            print(f"nearsub view: log {str(path)!r} has no state messages to replay", file=sys.stderr)
            return 2
    except MissionError as exc:
        print(f"nearsub view: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # not an MCAP file, or an unreadable one
        print(f"nearsub view: {path}: not a readable log ({exc})", file=sys.stderr)
        return 2
    return _serve(serve_viewer(source, port, ViewerAccess.for_mission(None), _ready), port)


def mission_endpoints(community: str, connect: list[str] | None, run_file: str | None):
    """(endpoints, mission or None, log path or None, credentials file or None) of a running
    mission: from the launcher's run file, from --connect, or from the registry (LookupError when
    it is not running)."""
    from ..support import registry

    # Credentials from the registry; None falls back to $NEARSUB_CREDENTIALS (the launcher's children).
    if run_file:
        from nearsub.common.mission.schema import RunConfig

        try:
            run = RunConfig.load(run_file)
        except (OSError, ValueError) as exc:
            raise InputError(f"--run {run_file}: not a readable run file ({exc.__class__.__name__})") from None
        log = Path(run.log_dir) / f"{run.mission.name}.mcap"  # where the launcher's logger writes
        credentials = registry.running().get(run.mission.name, {}).get("credentials")
        return tuple(connect or run.connect), run.mission, log, credentials
    if connect:
        return tuple(connect), None, None, None
    entry = registry.lookup(community)
    return tuple(entry["connect"]), mission_of_run(entry), entry.get("log"), entry.get("credentials")


def _live(community: str, connect: list[str] | None, run_file: str | None, port: int) -> int:
    from nearsub.common.runtime import credentials as mission_credentials
    from nearsub.common.runtime.bus import Bus, Endpoints

    from ..view_server import LiveSource, ViewerAccess, serve_viewer

    endpoints, mission, log, credentials = mission_endpoints(community, connect, run_file)
    try:
        access = ViewerAccess.for_mission(credentials or mission_credentials.from_environment())
    except mission_credentials.CredentialsError as exc:
        raise InputError(str(exc)) from None

    async def main() -> None:
        with Bus(Endpoints("client", endpoints, credentials=credentials)) as bus:
            await serve_viewer(LiveSource(bus, community, mission, log), port, access, _ready)

    return _serve(main(), port)
