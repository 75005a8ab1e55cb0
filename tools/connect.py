"""Open a bus to a running mission: by explicit endpoint, or by community name via the registry."""

from __future__ import annotations

import time
import uuid

from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Bus, Endpoints, Mailbox
from nearsub.common.runtime.messages import Control, ControlReply, MessageError, decode, encode

from . import registry


def add_connect_arguments(parser) -> None:
    parser.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="router endpoint, e.g. tcp/127.0.0.1:7447"
    )
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


class Caller:
    """Request/reply over the bus: control requests travel as ordinary (logged) messages and the
    answer comes back on nearsub/<community>/reply/<name>."""

    def __init__(self, bus: Bus, community: str, name: str):
        self.bus = bus
        self.community = community
        self.name = name
        self.replies = Mailbox()
        bus.subscribe(keys.reply(community, name), self.replies)

    def call(self, target: str, cmd: str, timeout: float, **args) -> ControlReply | None:
        """Send `cmd` to `target` ("clock" or an app instance); None if no reply in time."""
        request = Control(
            step=0, t=0.0, source=self.name, cmd=cmd, args=args, request_id=uuid.uuid4().hex, reply_to=self.name
        )
        self.bus.put_when_matched(keys.control(self.community, target), encode(request))
        end = time.monotonic() + timeout
        while (remaining := end - time.monotonic()) > 0:
            mail = self.replies.get(timeout=remaining)
            if mail is None:
                break
            try:
                reply = decode(mail.payload, ControlReply, mail.key)
            except MessageError:
                continue
            if reply.request_id == request.request_id:
                return reply
        return None
