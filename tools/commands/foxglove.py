"""`nearsub foxglove MISSION` and `nearsub log export --format foxglove`: a mission for Foxglove.

Both go through foxglove-sdk: an MCAP file it writes, or its WebSocket server on 127.0.0.1
(Foxglove's WebSocket protocol, subprotocol "foxglove.sdk.v1"), following a running mission. The channels are those of
`nearsub.common.viewer.foxglove`: every nearsub topic as JSON with its schema, plus the scene in
Foxglove's schemas (`/tf`, `/scene/mission`, `/scene/uuv`, `/events`). Log times are on the
epoch: the mission's start wall time (recorded in the log when the logger starts) plus simulated
time; each message keeps its simulated time.

Who can read the server: Foxglove's WebSocket protocol has no authentication, and foxglove-sdk
0.30's `start_server` offers none either (host, port, TLS for encryption, a channel filter and
listener callbacks, none of which can refuse a client), so every local user who finds the port
can read the whole mission. It listens on loopback only, on a random free port by default, and
advertises no capability a client could use to publish, set parameters or call services: the
server shows the mission, it never controls it.
"""

from __future__ import annotations

import time
from pathlib import Path

from ..support.missions import add_mission_argument, mission_name
from .view import PORT

REPUBLISH = 2.0  # wall seconds between repeats of the fixed scene, for clients that join late


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("foxglove", help="serve a running mission to Foxglove (WebSocket, 127.0.0.1)")
    add_mission_argument(p)
    p.add_argument(
        "--port",
        type=PORT,
        default=0,
        help="TCP port on 127.0.0.1 (default: a free one, printed; Foxglove's own default is 8765)",
    )
    p.add_argument("--connect", action="append", metavar="ENDPOINT", help="router endpoint instead of the registry")
    p.add_argument("--run", metavar="RUN.json", help="the launcher's run file instead of the registry")
    p.set_defaults(func=foxglove_command)


class _Channels:
    """One foxglove-sdk channel per topic, made on first use, each with its JSON schema."""

    def __init__(self, context):
        self.context = context
        self.channels: dict = {}

    def log(self, topic: str, message: dict, log_time: int) -> None:
        import foxglove

        from nearsub.common.viewer.foxglove import schema_for, to_json

        channel = self.channels.get(topic)
        if channel is None:
            name, schema = schema_for(topic)
            channel = foxglove.Channel(
                topic,
                schema=foxglove.Schema(name=name, encoding="jsonschema", data=to_json(schema)),
                message_encoding="json",
                context=self.context,
            )
            self.channels[topic] = channel
        channel.log(to_json(message), log_time=log_time)


def export_foxglove(path: str | Path, output: str | Path) -> int:
    """Write the log at `path` as a Foxglove MCAP at `output`; returns the number of messages."""
    import foxglove

    from nearsub.common.runtime.alog import log_start
    from nearsub.common.runtime.logfile import INVALID_SUFFIX, read_log
    from nearsub.common.viewer.foxglove import FoxgloveScene
    from nearsub.logs import decode_payload

    from ..support.log_input import mission_of_log

    contents = read_log(path)
    start_ms = round(log_start(contents) * 1e3)  # the logger records its start to the millisecond
    scene = FoxgloveScene(mission_of_log(Path(path)), start_ms * 1_000_000)
    context = foxglove.Context()
    channels = _Channels(context)
    count = 0
    with foxglove.open_mcap(output, allow_overwrite=True, context=context) as writer:
        for name, values in contents.metadata.items():
            writer.write_metadata(name, values)
        for topic, message, ns in scene.static_updates(0.0):
            channels.log(topic, message, ns)
            count += 1
        for record in sorted(contents.records, key=lambda r: r.log_time):
            if record.topic.endswith(INVALID_SUFFIX):
                continue
            fields = decode_payload(record.data)
            if not isinstance(fields, dict):
                continue
            for topic, message, ns in scene.translate(record.topic, fields, record.sim_time):
                channels.log(topic, message, ns)
                count += 1
    return count


def serve_mission(bus, community: str, mission, port: int, ready) -> None:
    """Follow a running mission on `bus` and publish its channels on a foxglove-sdk WebSocket
    server on 127.0.0.1:`port`; `ready(url)` once it listens; until Ctrl-C or SIGTERM
    (it goes on after the mission's end, so a client keeps the last picture).
    The subscription is lossy: a slow Foxglove client never slows the mission down."""
    import foxglove

    from nearsub.common.viewer.foxglove import FoxgloveScene

    from ..support.connect import mission_messages
    from ..support.errors import InputError

    context = foxglove.Context()
    try:
        server = foxglove.start_server(name=f"nearsub {community}", host="127.0.0.1", port=port, context=context)
    except RuntimeError as exc:  # foxglove-sdk's error: the port cannot be bound
        raise InputError(f"--port {port}: cannot serve on 127.0.0.1 ({exc})") from None
    try:
        channels = _Channels(context)
        scene: FoxgloveScene | None = None
        sim_time, last_static = 0.0, 0.0
        ready(f"ws://127.0.0.1:{server.port}")
        for item in mission_messages(bus, community):
            if item is not None:
                key, fields = item
                sim_time = max(sim_time, float(fields.get("t", 0.0) or 0.0))
                if scene is None:  # simulated time 0 on the epoch: now, less what has run
                    scene = FoxgloveScene(mission, time.time_ns() - round(sim_time * 1e9))
                for topic, message, ns in scene.translate(key, fields, sim_time):
                    channels.log(topic, message, ns)
            if scene is not None and time.monotonic() - last_static >= REPUBLISH:
                last_static = time.monotonic()
                for topic, message, ns in scene.static_updates(sim_time):
                    channels.log(topic, message, ns)
    finally:
        server.stop()


def foxglove_command(args) -> int:
    from .view import mission_endpoints

    community = mission_name(args.mission)
    endpoints, mission, _, credentials = mission_endpoints(community, args.connect, args.run)
    from nearsub.common.runtime.bus import Bus, Endpoints

    def ready(url: str) -> None:
        print(f"nearsub foxglove: {url}", flush=True)

    try:
        with Bus(Endpoints("client", endpoints, credentials=credentials)) as bus:
            serve_mission(bus, community, mission, args.port, ready)
    except KeyboardInterrupt:  # the way to stop it
        pass
    return 0
