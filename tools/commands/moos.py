"""`nearsub moos sim FILE.moos [NAME]`: nearsub's sim in a MOOS community, as uSimMarineV22
(docs/moos.md). pAntler starts it with `InhibitMOOSParams = true` and the arguments in
`ExtraProcessParams` (missions/moos/). `nearsub moos watch MISSION --db HOST:PORT`: a running
nearsub mission posted to a MOOSDB, for pMarineViewer. Both need the `moos` extra (pymoos2)."""

from __future__ import annotations

import sys

from ..support.missions import add_mission_argument, mission_name


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("moos", help="nearsub in a MOOS-IvP community (needs the moos extra)")
    sub = p.add_subparsers(dest="moos_command", required=True, metavar="ACTION")
    sim = sub.add_parser("sim", help="the sim as a MOOS app: DESIRED_* in, NAV_* out (uSimMarineV22)")
    sim.add_argument("moos_file", help="the community's .moos file, with a ProcessConfig block for the sim")
    sim.add_argument("name", nargs="?", default="nearsub_sim", help="its MOOS name and ProcessConfig block")
    sim.set_defaults(func=sim_command)
    watch = sub.add_parser("watch", help="post a running nearsub mission to a MOOSDB for pMarineViewer")
    add_mission_argument(watch)
    watch.add_argument(
        "--db", default="localhost:9000", metavar="HOST:PORT", help="the MOOSDB (default localhost:9000)"
    )
    watch.add_argument("--connect", action="append", metavar="ENDPOINT", help="router endpoint instead of the registry")
    watch.add_argument("--run", metavar="RUN.json", help="the launcher's run file instead of the registry")
    watch.set_defaults(func=watch_command)


def sim_command(args) -> int:
    from nearsub.apps.entry import AppError
    from nearsub.apps.moos_sim import missing_client, run
    from nearsub.common.mission.cores import mission_surrogate
    from nearsub.common.mission.schema import MissionError
    from nearsub.common.moos.config import MoosConfigError, read_moos, sim_config
    from nearsub.common.moos.sim import sim_mission

    if problem := missing_client():
        print(f"nearsub moos: {problem}", file=sys.stderr)
        return 2
    try:
        config = sim_config(read_moos(args.moos_file), args.name)
        mission = sim_mission(config)
        surrogate = mission_surrogate(mission) if mission.needs_surrogate else None
    except (MoosConfigError, MissionError) as exc:
        print(f"nearsub moos sim: {exc}", file=sys.stderr)
        return 2
    try:
        return run(config, mission, args.name, surrogate)
    except AppError as exc:
        print(f"nearsub moos sim: {exc}", file=sys.stderr)
        return exc.code


REPUBLISH = 2.0  # wall seconds between posts of what moves with the submarine (hull, waypoints)


def db_address(text: str) -> tuple[str, int]:
    from ..support.errors import InputError

    host, _, port = text.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(f"--db {text}: expected HOST:PORT")
    return host, int(port)


def watch_command(args) -> int:
    from nearsub.apps.moos_sim import CONNECT_TIMEOUT, missing_client
    from nearsub.common.runtime.bus import Bus, Endpoints

    from ..support.errors import InputError
    from .view import mission_endpoints

    if problem := missing_client():
        print(f"nearsub moos: {problem}", file=sys.stderr)
        return 2
    host, port = db_address(args.db)
    community = mission_name(args.mission)
    endpoints, mission, _, credentials = mission_endpoints(community, args.connect, args.run)
    if mission is None:
        raise InputError(f"{community}: its mission is unknown with --connect alone; give --run RUN.json")
    from pymoos2.core.MOOSCommClient import MOOSCommClient

    client = MOOSCommClient(host, port, app_name="nearsub_watch", comm_tick=20.0)
    client.start()
    try:
        if not client.wait_until_connected(CONNECT_TIMEOUT):
            print(f"nearsub moos watch: no MOOSDB at {host}:{port} after {CONNECT_TIMEOUT:g} s", file=sys.stderr)
            return 1
        with Bus(Endpoints("client", endpoints, credentials=credentials)) as bus:
            follow(bus, community, mission, client)
        print("nearsub moos watch: lost the MOOSDB", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # the way to stop it
        return 0
    finally:
        client.stop()


def follow(bus, community: str, mission, client) -> None:
    """Post the mission's messages as they come (lossy: a slow MOOSDB never slows the mission),
    until the MOOSDB goes."""
    import time

    from nearsub.common.moos.watch import MissionWatch

    from ..support.connect import mission_messages

    watch, last_scene = MissionWatch(mission), -REPUBLISH
    for item in mission_messages(bus, community):
        if not client.is_connected:
            break
        if item is not None:
            for variable, value in watch.translate(*item):
                client.notify(variable, value)
        if time.monotonic() - last_scene >= REPUBLISH:
            last_scene = time.monotonic()
            for variable, value in watch.scene():
                client.notify(variable, value)
