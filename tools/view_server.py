"""The viewer's thin shell: a websocket server on loopback that serves the page and pushes frames.

`LiveSource` follows a running mission over the bus and sends the page's controls as the
existing control requests (the clock's pause/resume, the launcher's swap), so each action is in
the mission's log. `ReplaySource` plays a log file with a cursor the page scrubs. Both turn
messages into pictures through `nearsub.common.viewer.scene`; this module only moves bytes.

The page and its script ship as package data (`nearsub/common/viewer/static`); the server serves
them over plain HTTP on the same port as the websocket (`/ws`), so the page fetches nothing else.

Access (docs/design.md, "Transport"): the page and the websocket need a token in the URL
(`?token=`), as Jupyter's do; the control token may pause, warp, resume and swap, the read-only
token only watches. A websocket whose `Origin` is not the page's own is refused, so a web page
open elsewhere in the user's browser cannot drive the mission. The page's script and style are
the package's public files and are served to anyone.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import secrets
import sys
import time
import uuid
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import msgpack
from websockets.asyncio.server import ServerConnection, broadcast, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from nearsub.common.runtime import credentials as mission_credentials
from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Bus, Mailbox
from nearsub.common.runtime.logfile import read_log
from nearsub.common.viewer.scene import SceneModel, feed_payload, static_scene

from .support.caller import Caller

TICK = 0.1  # wall seconds between frames pushed to the page
MAX_MAIL_PER_TICK = 20000  # keep the server responsive at warp 0 (the newest state is what counts)
STATIC_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript", ".css": "text/css"}


PAGES = ("/", "/index.html")  # what needs a token besides the websocket: the page itself
READ_ONLY_COMMANDS = {"status"}  # what a read-only page may ask: nothing that changes the mission


@dataclass(frozen=True)
class ViewerAccess:
    """The viewer's two tokens: `control` drives the mission, `view` only watches."""

    control: str
    view: str

    @classmethod
    def for_mission(cls, credentials_file: str | Path | None) -> ViewerAccess:
        """Derived from the mission's credentials, so every viewer of the mission (the launcher's,
        `nearsub view NAME` of its owner) has the same URLs and only holders of the credentials
        can compute them; random for a mission without credentials and for a replay."""
        if credentials_file is None:
            return cls(secrets.token_hex(16), secrets.token_hex(16))
        held = mission_credentials.load(credentials_file)
        return cls(mission_credentials.derive(held, "viewer control"), mission_credentials.derive(held, "viewer view"))

    def role(self, token: str) -> str | None:
        """ "control", "view" or None (no valid token), compared in constant time."""
        if hmac.compare_digest(token.encode(), self.control.encode()):
            return "control"
        if hmac.compare_digest(token.encode(), self.view.encode()):
            return "view"
        return None

    def urls(self, port: int) -> str:
        """The line a user opens: the control URL, then the read-only one."""
        base = f"http://127.0.0.1:{port}/?token="
        return f"{base}{self.control} (read-only: {base}{self.view})"


def static_files() -> dict[str, tuple[bytes, str]]:
    """URL path -> (body, content type) of every file the page needs."""
    root = resources.files("nearsub.common.viewer") / "static"
    files = {}
    for item in root.iterdir():
        suffix = Path(item.name).suffix
        if suffix in STATIC_TYPES:
            files[f"/{item.name}"] = (item.read_bytes(), STATIC_TYPES[suffix])
    files["/"] = files["/index.html"]
    return files


class LiveSource:
    """A running mission: messages from the bus, controls through the clock and the launcher."""

    mode = "live"

    def __init__(self, bus: Bus, community: str, mission, history: str | Path | None = None):
        self.bus = bus
        self.community = community
        self.mission = mission
        self.scene = static_scene(mission, source=community) | {"mode": "live", "community": community}
        self.model = SceneModel.for_mission(mission)
        self.mailbox = Mailbox()
        c = community
        for leaf in ("state", "forces", "helm"):
            bus.subscribe(keys.vehicle_topic(c, "*", leaf), self.mailbox)
        bus.subscribe(keys.all_events(c), self.mailbox)
        bus.subscribe(keys.mission_end(c), self.mailbox)
        if history is not None and Path(history).is_file():
            # What happened before the viewer joined: the log the mission is writing (complete
            # chunks only); the subscriptions above are already declared, so nothing falls between.
            for record in read_log(history).records:
                feed_payload(self.model, record.topic, record.data)
        self.caller = Caller(bus, c, f"viewer-{uuid.uuid4().hex[:8]}")
        self.calls = asyncio.Lock()  # one request at a time: Caller matches replies by id
        self.last_state_wall = time.monotonic()
        self.last_status = 0.0
        self.status_task: asyncio.Task | None = None

    def tick(self) -> dict:
        now = time.monotonic()
        for _ in range(MAX_MAIL_PER_TICK):
            mail = self.mailbox.get(timeout=0)
            if mail is None:
                break
            if feed_payload(self.model, mail.key, mail.payload, now) and mail.key.endswith("/state"):
                self.last_state_wall = now
        # Ask the clock whether it is paused only when the states stop (a pause someone else asked
        # for, a swap, a pause_at_step); a running mission needs no status requests.
        quiet = now - self.last_state_wall > 1.0
        if (quiet or self.model.paused is None) and now - self.last_status > 3.0 and self.model.end is None:
            self.last_status = now
            if self.status_task is None or self.status_task.done():
                self.status_task = asyncio.ensure_future(self.command({"cmd": "status"}))
        if self.model.end is not None:
            self.model.paused = None
        return self.model.frame(now=now)

    async def _clock(self, cmd: str, **args):
        async with self.calls:
            return await asyncio.to_thread(self.caller.call, "clock", cmd, self.mission_step_timeout(), **args)

    def mission_step_timeout(self) -> float:
        return (self.mission.step_timeout if self.mission is not None else 10.0) + 5.0

    async def command(self, request: dict) -> dict:
        cmd = request.get("cmd")
        if cmd in ("pause", "resume", "status"):
            reply = await self._clock(cmd)
            if reply is None:
                return {"type": "reply", "cmd": cmd, "ok": False, "text": "the clock did not answer"}
            if reply.ok and cmd == "pause":
                self.model.paused = True
            elif reply.ok and cmd == "resume":
                self.model.paused = False
            elif reply.ok:
                self.model.paused = bool(reply.data.get("paused"))
                if isinstance(reply.data.get("warp"), (int, float)):  # a clock that reports its warp
                    self.model.requested_warp = float(reply.data["warp"])
            text = f"{cmd}: step {reply.data.get('step')}" if reply.ok else reply.error
            return {"type": "reply", "cmd": cmd, "ok": reply.ok, "text": text, "data": reply.data}
        if cmd == "warp":
            try:
                warp = float(request.get("warp"))
            except (TypeError, ValueError):
                text = f"warp {request.get('warp')!r} is not a number"
                return {"type": "reply", "cmd": cmd, "ok": False, "text": text}
            reply = await self._clock("warp", warp=warp)
            if reply is None:
                return {"type": "reply", "cmd": cmd, "ok": False, "text": "the clock did not answer"}
            if reply.ok:
                self.model.requested_warp = warp
            return {"type": "reply", "cmd": cmd, "ok": reply.ok, "text": f"warp {warp:g}" if reply.ok else reply.error}
        if cmd == "swap":
            return await self._swap(str(request.get("behaviour", "")))
        return {"type": "reply", "cmd": cmd, "ok": False, "text": f"unknown command {cmd!r}"}

    async def _swap(self, behaviour: str) -> dict:
        """The helm swap of `nearsub swap MISSION helm --behaviour B`, asked of the launcher."""
        if behaviour not in self.scene["behaviours"]:
            return {"type": "reply", "cmd": "swap", "ok": False, "text": f"behaviour {behaviour!r} is not known"}
        request = msgpack.packb({"cmd": "swap", "app": "helm", "set": [f"behaviour={behaviour}"], "at_step": None})
        timeout = self.mission_step_timeout() + (self.mission.startup_timeout if self.mission is not None else 30.0)
        async with self.calls:
            replies = await asyncio.to_thread(self.bus.request, keys.launcher_control(self.community), request, timeout)
        if not replies:
            return {"type": "reply", "cmd": "swap", "ok": False, "text": "the launcher did not answer"}
        ok, payload = replies[0]
        if not ok:
            return {"type": "reply", "cmd": "swap", "ok": False, "text": payload.decode(errors="replace")}
        result = msgpack.unpackb(payload)
        if "refused" in result:
            return {"type": "reply", "cmd": "swap", "ok": False, "text": result["refused"]}
        text = f"swapped {result['old']} -> {result['new']} at step {result['step']}"
        return {"type": "reply", "cmd": "swap", "ok": True, "text": text}


class ReplaySource:
    """A log file: every message fed once, then a cursor in simulated time (play, pause, seek)."""

    mode = "replay"

    def __init__(self, path: str | Path, mission):
        contents = read_log(path)
        self.mission = mission
        self.scene = static_scene(mission, source=str(path)) | {"mode": "replay"}
        self.model = SceneModel.for_mission(mission)
        self.model.requested_warp = None
        for record in contents.records:
            feed_payload(self.model, record.topic, record.data)
        start, end = self.model.time_range()
        self.scene["range"] = [start, end]
        self.scene["damage"] = contents.damage
        if contents.damage:  # the replay shows what was kept; the user must know it is not all
            print(f"nearsub view: {path}: {contents.damage}", file=sys.stderr, flush=True)
        self.cursor = start
        self.playing = False
        self.rate = 1.0
        self.last_tick = time.monotonic()

    def tick(self) -> dict:
        now = time.monotonic()
        if self.playing:
            start, end = self.model.time_range()
            self.cursor = min(end, self.cursor + self.rate * (now - self.last_tick))
            if self.cursor >= end:
                self.playing = False
        self.last_tick = now
        frame = self.model.frame(self.cursor)
        frame["replay"] = {"cursor": self.cursor, "playing": self.playing, "rate": self.rate}
        return frame

    async def command(self, request: dict) -> dict:
        cmd = request.get("cmd")
        start, end = self.model.time_range()
        try:
            if cmd == "seek":
                self.cursor = min(end, max(start, float(request["t"])))
            elif cmd == "play":
                if self.cursor >= end:
                    self.cursor = start
                self.playing = True
            elif cmd in ("stop", "pause"):
                self.playing = False
            elif cmd == "rate":
                rate = float(request["rate"])
                if not rate > 0:
                    raise ValueError(f"rate must be > 0, got {rate}")
                self.rate = rate
            else:
                return {"type": "reply", "cmd": cmd, "ok": False, "text": f"a replay has no command {cmd!r}"}
        except (KeyError, TypeError, ValueError) as exc:
            return {"type": "reply", "cmd": cmd, "ok": False, "text": f"{cmd}: {exc}"}
        return {"type": "reply", "cmd": cmd, "ok": True, "text": f"{cmd} at t = {self.cursor:.2f} s"}


async def serve_viewer(source, port: int, access: ViewerAccess, ready=None, stop: asyncio.Event | None = None) -> None:
    """Serve the page and the websocket on 127.0.0.1:port until `stop` is set (forever if None),
    to holders of `access`'s tokens. `ready(urls)` is called once the socket listens."""
    files = static_files()
    clients: set[ServerConnection] = set()
    roles: dict[ServerConnection, str] = {}

    def process_request(connection: ServerConnection, request: Request) -> Response | None:
        url = urlsplit(request.path)
        path = url.path
        if path == "/ws" or path in PAGES:
            role = access.role(parse_qs(url.query).get("token", [""])[0])
            if role is None:
                return connection.respond(403, "a token is needed: open the URL nearsub printed\n")
            if path == "/ws":
                origin = request.headers.get("Origin")
                own = {f"http://{host}:{connection.local_address[1]}" for host in ("127.0.0.1", "localhost")}
                if origin is not None and origin not in own:  # a browser page of another site
                    return connection.respond(403, f"origin {origin} is not this viewer's\n")
                roles[connection] = role
                return None  # the websocket handshake
        if path not in files:
            return connection.respond(404, f"no such page: {path}\n")
        body, content_type = files[path]
        headers = Headers({"Content-Type": content_type, "Content-Length": str(len(body)), "Cache-Control": "no-store"})
        return Response(200, "OK", headers, body)

    async def handler(connection: ServerConnection) -> None:
        clients.add(connection)
        try:
            await connection.send(json.dumps(source.scene | {"control": roles.get(connection) == "control"}))
            await connection.send(json.dumps(source.tick()))
            async for text in connection:
                try:
                    request = json.loads(text)
                except ValueError:
                    continue
                if not isinstance(request, dict):
                    continue
                if roles.get(connection) != "control" and request.get("cmd") not in READ_ONLY_COMMANDS:
                    cmd = request.get("cmd")
                    reply = {"type": "reply", "cmd": cmd, "ok": False, "text": f"{cmd}: this page is read-only"}
                else:
                    reply = await source.command(request)
                await connection.send(json.dumps(reply))
        except ConnectionClosed:
            pass  # the page went away (closed, reloaded) while a command ran
        finally:
            clients.discard(connection)
            roles.pop(connection, None)

    async with serve(handler, "127.0.0.1", port, process_request=process_request) as server:
        bound = server.sockets[0].getsockname()[1]
        if ready is not None:
            ready(access.urls(bound))
        last = ""
        while stop is None or not stop.is_set():
            text = json.dumps(source.tick())
            if text != last and clients:
                broadcast(clients, text)
                last = text
            await asyncio.sleep(TICK)
