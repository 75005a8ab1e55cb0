"""`nearsub log play`: republish a mission log onto the bus (MOOS-IvP's uPlayBack, `ros2 bag play`),
so that `tap`, `view` or a new app run on a replay as on a live mission.

Every selected message goes out with its logged bytes, unchanged, at its logged simulated time
scaled by the warp (warp 0: as fast as the bus takes them), in log-time order (messages logged at
the same time keep the log's order), one lossless publisher per key (docs/design.md, "Transport").
Under `--name NAME` the keys move from `nearsub/<logged>/...` to `nearsub/<NAME>/...`; the
payloads stay as logged, so a control request's `reply_to` still names the logged mission. The new
name is an option, not the MISSION positional of the commands that address a running mission: the
positional is the log, and the name is one the replay claims, not one that must be running.

Without `--connect` the player starts a router on a free loopback port as the launcher does
(`launcher.processes.spawn_router`) and prints its endpoint. It claims the name and registers the
replay like a launched mission (`registry`), so `nearsub tap echo NAME KEY` and
`nearsub view NAME` find it by name; a live mission of that name is refused rather than mixed with.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from .support import registry
from .support.arguments import number
from .support.errors import InputError

COMMUNITY_CHARS = "letters, digits, '_' and '-'"


class PlayInputError(InputError):
    """Bad command-line input; the one-line text names the option and its value."""


@dataclass
class Selection:
    community: str  # the community the keys are published under
    logged: str  # the community of the log
    items: list[tuple[int, str, bytes]]  # (log_time ns, published key, payload)
    startup_timeout: float


def add_arguments(t) -> None:
    t.add_argument("log")
    t.add_argument(
        "--warp",
        type=number(minimum=0.0),
        default=1.0,
        help="simulated seconds per wall second (0: as fast as possible)",
    )
    t.add_argument(
        "--from", dest="start", type=number(minimum=0.0), metavar="T", help="first simulated second to replay"
    )
    t.add_argument("--to", dest="end", type=number(minimum=0.0), metavar="T", help="last simulated second to replay")
    t.add_argument("--topic", help="key expression of the logged keys to replay (wildcards * and **)")
    t.add_argument("--vehicle", metavar="NAME", help="replay one vehicle's keys and the mission-wide ones")
    t.add_argument("--name", help="publish as the mission of this name (default: the logged one)")
    t.add_argument("--connect", action="append", metavar="ENDPOINT", help="use this router instead of starting one")
    t.add_argument(
        "--wait",
        type=number(minimum=0.0),
        default=0.0,
        metavar="S",
        help="wait up to S wall seconds for a subscriber before playing",
    )
    t.add_argument(
        "--linger",
        type=number(minimum=0.0),
        default=1.0,
        metavar="S",
        help="keep the bus up S wall seconds after the last message",
    )


def select(args) -> Selection:
    """The messages to replay, checked against the arguments; PlayInputError names a bad one."""
    from nearsub.common.mission.schema import COMMUNITY_PATTERN
    from nearsub.common.runtime.logfile import INVALID_SUFFIX, read_log

    from .support.log_input import topic_filter, vehicle_records

    if args.connect:  # before a name is claimed; a malformed endpoint is bad input, not a lost bus
        from nearsub.common.runtime.bus import BusError, check_endpoints

        try:
            check_endpoints("connect", args.connect)
        except BusError as exc:
            raise PlayInputError(str(exc)) from None
    if args.start is not None and args.end is not None and args.end < args.start:
        raise PlayInputError(f"--to {args.end:g}: before --from {args.start:g}")
    if args.name is not None and not COMMUNITY_PATTERN.match(args.name):
        raise PlayInputError(f"--name {args.name!r}: use {COMMUNITY_CHARS}")
    wanted = topic_filter(args.topic)
    contents = read_log(args.log)
    records = contents.records
    if args.vehicle is not None:
        records = vehicle_records(contents, args, error=PlayInputError)
    logged = contents.metadata.get("mission", {}).get("name") or next(
        (r.topic.split("/")[1] for r in contents.records if r.topic.count("/") >= 2), "nearsub"
    )
    community = args.name or logged
    startup_timeout = 30.0
    try:
        startup_timeout = float(json.loads(contents.metadata["mission"]["resolved"])["startup_timeout"])
    except (KeyError, ValueError, TypeError):
        pass
    start_ns = None if args.start is None else int(round(args.start * 1e9))
    end_ns = None if args.end is None else int(round(args.end * 1e9))
    old_prefix, new_prefix = f"nearsub/{logged}/", f"nearsub/{community}/"
    items = []
    for r in sorted(records, key=lambda r: r.log_time):  # stable: equal times keep file order
        key = r.topic.removesuffix(INVALID_SUFFIX)  # undecodable payloads replay on their own key
        if not wanted(key):
            continue
        if (start_ns is not None and r.log_time < start_ns) or (end_ns is not None and r.log_time > end_ns):
            continue
        if key.startswith(old_prefix):
            key = new_prefix + key[len(old_prefix) :]
        items.append((r.log_time, key, bytes(r.data)))
    if not items:
        what = f"--topic {args.topic}" if args.topic else "--from/--to"
        raise PlayInputError(f"{what}: no message of {args.log} matches")
    return Selection(community, logged, items, startup_timeout)


def play_command(args) -> int:
    from .support.log_input import check_log

    check_log(Path(args.log))
    selection = select(args)
    try:
        claim = registry.claim(selection.community)
    except registry.NameTaken:
        print(
            f"nearsub log play: --name {selection.community}: a mission of that name is running; "
            "replay under another name with --name NAME",
            file=sys.stderr,
        )
        return 2
    folder = Path(tempfile.mkdtemp(prefix=f"play-{selection.community}-", dir=registry.runtime_dir()))
    router = None
    try:
        with claim:
            from nearsub.common.runtime.processes import stop

            from .launcher.processes import LaunchError, spawn_router

            credentials = None  # with --connect: $NEARSUB_CREDENTIALS, if the router needs any
            try:
                if args.connect:
                    connect = list(args.connect)
                else:
                    credentials = str(folder / "credentials")
                    router, connect = spawn_router(folder, selection.startup_timeout, Path(credentials))
            except LaunchError as exc:
                print(f"nearsub log play: {exc}", file=sys.stderr)
                return 1
            try:
                return _play(args, selection, connect, router is not None, credentials)
            except KeyboardInterrupt:
                return 130
            finally:
                (registry.runtime_dir() / f"{selection.community}.json").unlink(missing_ok=True)
                if router is not None:
                    stop([router], grace=0.0)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _play(args, selection: Selection, connect: list[str], own_router: bool, credentials: str | None) -> int:
    from nearsub.common.runtime.bus import Bus, BusError, Endpoints

    try:
        endpoints = Endpoints("client", tuple(connect), timeout=selection.startup_timeout, credentials=credentials)
        with Bus(endpoints) as bus:
            return _publish(args, selection, bus, connect, own_router, credentials)
    except BusError as exc:
        print(f"nearsub log play: {exc}", file=sys.stderr)
        return 1


def _publish(args, selection: Selection, bus, connect: list[str], own_router: bool, credentials: str | None) -> int:
    from nearsub.common.runtime import keys

    c = selection.community
    publishers = {}
    for _, key, _ in selection.items:
        if key not in publishers:
            publishers[key] = bus.publisher(key)
    bus.token(keys.alive(c, "player", "player"))
    registry.register(c, connect, str(Path(args.log).resolve()), credentials)
    first, last = selection.items[0][0] / 1e9, selection.items[-1][0] / 1e9
    router = "started" if own_router else "given"
    print(f"router {connect[0]} ({router})", flush=True)
    print(
        f"playing {len(selection.items)} messages of {len(publishers)} keys, simulated {first:.2f} .. {last:.2f} s, "
        f"as mission {c} at warp {args.warp:g}",
        flush=True,
    )
    if args.wait > 0 and not _wait_for_subscriber(publishers.values(), args.wait):
        print(f"nearsub log play: no subscriber within --wait {args.wait:g} s; playing anyway", file=sys.stderr)
    begin = time.monotonic()
    for log_time, key, payload in selection.items:
        if args.warp > 0:
            delay = begin + (log_time / 1e9 - first) / args.warp - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        publishers[key].put(payload)
    wall = time.monotonic() - begin
    print(f"played {len(selection.items)} messages in {wall:.2f} wall s", flush=True)
    time.sleep(args.linger)
    return 0


def _wait_for_subscriber(publishers, seconds: float) -> bool:
    """Whether some subscriber matched one of the publishers within `seconds`: data put before a
    subscription is known to the publishing session is not delivered (docs/design.md, "Transport")."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if any(_matched(p) for p in publishers):
            return True
        time.sleep(0.01)
    return False


def _matched(publisher) -> bool:
    # bus.Publisher keeps its Zenoh publisher private and has no matching status of its own yet.
    # zenoh 1.10 returns a MatchingStatus object (always truthy) whose `matching` is the answer,
    # although its stub says bool.
    inner = getattr(publisher, "_publisher", None)
    if inner is None:
        return False
    status = inner.matching_status
    return bool(getattr(status, "matching", status))
