"""Request/reply to the clock or an app of a running mission, for the launcher and the tools."""

from __future__ import annotations

import time
import uuid

from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Bus, Mailbox
from nearsub.common.runtime.messages import Control, ControlReply, MessageError, decode, encode


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
