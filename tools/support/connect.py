"""Open a bus to a running mission: by explicit endpoint, or by community name via the registry."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from . import registry

if TYPE_CHECKING:
    from nearsub.common.runtime.bus import Bus


def add_connect_arguments(parser) -> None:
    add_router_argument(parser)
    parser.add_argument("--community", help="mission (community) name; default: from the key, or the only running one")


def add_router_argument(parser) -> None:
    """`--connect` and `--credentials` for the tools that name their mission as a positional argument."""
    parser.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="router endpoint (default: from the registry)"
    )
    parser.add_argument(
        "--credentials",
        metavar="FILE",
        help="the router's user:password file (default: the registry's, else $NEARSUB_CREDENTIALS)",
    )


def community_from_key(key: str | None) -> str | None:
    parts = (key or "").split("/")
    if len(parts) >= 2 and parts[0] == "nearsub" and parts[1] not in ("*", "**"):
        return parts[1]
    return None


def open_bus(args, key: str | None = None) -> tuple[Bus, str | None]:
    """A client bus for a tool, and the community it resolved (None when unknown). The registry is
    read first, so that a tool with no mission to talk to says so before Zenoh loads. The
    credentials are those the launcher recorded for the mission, unless given."""
    community = args.community or community_from_key(key)
    credentials = args.credentials
    if args.connect:
        connect = args.connect
    else:
        entry = registry.lookup(community)
        connect, community = entry["connect"], entry["community"]
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
