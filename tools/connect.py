"""Open a bus to a running mission: by explicit endpoint, or by community name via the registry."""

from __future__ import annotations

from nearsub.common.bus import Bus, Endpoints

from . import registry


def add_connect_arguments(parser) -> None:
    parser.add_argument("--connect", action="append", metavar="ENDPOINT", help="router endpoint, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--community", help="mission (community) name; default: from the key, or the only running one")


def community_from_key(key: str | None) -> str | None:
    parts = (key or "").split("/")
    if len(parts) >= 2 and parts[0] == "nearsub" and parts[1] not in ("*", "**"):
        return parts[1]
    return None


def open_bus(args, key: str | None = None) -> tuple[Bus, str | None]:
    """A client bus for a tool, and the community it resolved (None when unknown)."""
    community = args.community or community_from_key(key)
    if args.connect:
        return Bus(Endpoints("client", tuple(args.connect))), community
    entry = registry.lookup(community)
    return Bus(Endpoints("client", tuple(entry["connect"]))), entry["community"]
