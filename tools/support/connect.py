"""Open a bus to a running mission: by explicit endpoint, or by its name via the registry."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from . import registry
from .missions import add_mission_argument, mission_name

if TYPE_CHECKING:
    from nearsub.common.runtime.bus import Bus


def add_connect_arguments(parser) -> None:
    """MISSION (`missions.add_mission_argument`), then `--connect` and `--credentials`."""
    add_mission_argument(parser)
    add_router_argument(parser)


def add_router_argument(parser) -> None:
    """`--connect` and `--credentials`: a router instead of the registry's, and its credentials."""
    parser.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="router endpoint (default: from the registry)"
    )
    parser.add_argument(
        "--credentials",
        metavar="FILE",
        help="the router's user:password file (default: the registry's, else $NEARSUB_CREDENTIALS)",
    )


def open_bus(args) -> tuple[Bus, str]:
    """A client bus to the mission `args.mission` names, and its name. The registry is read
    first, so that a tool with no mission to talk to says so before Zenoh loads. The credentials
    are those the launcher recorded for the mission, unless given."""
    community = mission_name(args.mission)
    credentials = args.credentials
    if args.connect:
        connect = args.connect
    else:
        entry = registry.lookup(community)
        connect = entry["connect"]
        credentials = credentials or entry.get("credentials")
    from nearsub.common.runtime.bus import Bus, Endpoints

    return Bus(Endpoints("client", tuple(connect), credentials=credentials)), community


def mission_messages(bus: Bus, community: str, idle: float = 0.02):
    """A running mission's messages as (key, fields) as they come, lossy (a slow consumer never
    slows the mission down); None after `idle` wall seconds without one, for the caller's periodic
    work. Payloads that are not a message's fields are skipped."""
    from nearsub.common.runtime import keys
    from nearsub.logs import decode_payload

    stream = bus.stream(keys.everything(community), lossy=True)
    while True:
        item = stream.try_recv()
        if item is None:
            time.sleep(idle)
            yield None
            continue
        key, payload = item
        try:
            fields = decode_payload(payload)
        except ValueError:
            continue
        if isinstance(fields, dict):
            yield key, fields
