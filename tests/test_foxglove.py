"""Logs and live missions for Foxglove: `nearsub log export --format foxglove` writes an MCAP whose
channels are all JSON with JSON schemas (nearsub's topics and Foxglove's scene schemas), on the
epoch of the mission's start; `nearsub foxglove NAME` serves a running mission over Foxglove's
WebSocket protocol."""

import json
import math

import pytest
from logsample import STARTED_UNIX, write_sample_log
from mcap.reader import make_reader

from conftest import nearsub

FOXGLOVE_SCHEMAS = {"/tf": "foxglove.FrameTransform", "/scene/mission": "foxglove.SceneUpdate",
                    "/scene/uuv": "foxglove.SceneUpdate", "/events": "foxglove.Log"}  # fmt: skip
START_NS = round(STARTED_UNIX * 1e3) * 1_000_000


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    folder = tmp_path_factory.mktemp("foxglove")
    write_sample_log(folder / "alpha.mcap", shuffle=True)
    target = folder / "alpha-foxglove.mcap"
    out = nearsub("log", "export", str(folder / "alpha.mcap"), "--format", "foxglove", "-o", str(target))
    assert out.returncode == 0, out.stderr
    with open(target, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = [(ch.topic, m.log_time, json.loads(m.data)) for _, ch, m in reader.iter_messages()]
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    channels = {ch.topic: (ch, summary.schemas[ch.schema_id]) for ch in summary.channels.values()}
    return channels, messages, metadata


def by_topic(messages, topic):
    return [(t, m) for name, t, m in messages if name == topic]


def test_every_channel_is_json_with_a_json_schema(exported):
    channels, _, _ = exported
    for topic, (channel, schema) in channels.items():
        assert channel.message_encoding == "json" and schema.encoding == "jsonschema", topic
        assert json.loads(schema.data)["type"] == "object"
    assert channels["nearsub/alpha/remus100/state"][1].name == "nearsub.State"
    for topic, name in FOXGLOVE_SCHEMAS.items():
        assert channels[topic][1].name == name
    transform = json.loads(channels["/tf"][1].data)["properties"]
    assert set(transform) == {"timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"}


def test_uuv_poses_follow_the_state_topic_on_the_mission_epoch(exported):
    _, messages, _ = exported
    states = sorted(by_topic(messages, "nearsub/alpha/remus100/state"), key=lambda item: item[0])
    transforms = by_topic(messages, "/tf")
    assert len(transforms) == len(states) > 100
    for (t_state, state), (t_tf, tf) in zip(states, transforms, strict=True):
        assert t_tf == t_state == START_NS + round(state["t"] * 1e9)  # simulated time on the epoch
        assert tf["timestamp"] == {"sec": t_tf // 10**9, "nsec": t_tf % 10**9}
        assert (tf["parent_frame_id"], tf["child_frame_id"]) == ("world", "remus100")
        assert (tf["translation"]["x"], tf["translation"]["y"]) == (state["x"], state["y"])
        yaw = 2 * math.atan2(tf["rotation"]["z"], tf["rotation"]["w"])
        assert math.remainder(yaw - state["psi"], 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    (_, uuv), = by_topic(messages, "/scene/uuv")  # fmt: skip
    entity = uuv["entities"][0]
    assert entity["frame_id"] == "remus100" and entity["frame_locked"]  # carried by /tf
    assert entity["cylinders"][0]["size"]["z"] == pytest.approx(1.33)  # the REMUS 100 to scale


def test_scene_has_the_tracks_and_events_are_log_lines(exported):
    _, messages, metadata = exported
    (t, mission), = by_topic(messages, "/scene/mission")  # fmt: skip
    assert t == START_NS
    lines = mission["entities"][0]["lines"]
    assert len(lines) == 2 and lines[0]["points"][0] == {"x": 0.0, "y": -20.0, "z": 0.0}  # alpha: no submarine
    events = by_topic(messages, "nearsub/alpha/events/sim") + by_topic(messages, "nearsub/alpha/events/helm")
    logs = by_topic(messages, "/events")
    assert len(logs) == sum(len(by_topic(messages, k)) for k in {n for n, _, _ in messages if "/events/" in n})
    assert events and all(log["message"].startswith("t=") and log["level"] in (2, 3, 4) for _, log in logs)
    assert metadata["mission"]["name"] == "alpha"


def test_export_refuses_to_overwrite_its_input_and_a_topic_selection(tmp_path):
    write_sample_log(tmp_path / "alpha.mcap", seconds=1.0)
    for extra, words in ((["-o", str(tmp_path / "alpha.mcap")], "is the log being exported"),
                         (["--topic", "nearsub/**"], "keeps every topic")):  # fmt: skip
        out = nearsub("log", "export", str(tmp_path / "alpha.mcap"), "--format", "foxglove", *extra)
        assert out.returncode == 2 and words in out.stderr and len(out.stderr.strip().splitlines()) == 1


def test_live_server_advertises_the_channels_and_streams_poses(launches, community):
    """`nearsub foxglove NAME` as `nearsub launch --foxglove` starts it (from the run file): a
    client sees the channels advertised and receives poses. foxglove-sdk's server speaks
    Foxglove's WebSocket protocol under its current name, "foxglove.sdk.v1" (the messages of
    "foxglove.websocket.v1", which it no longer accepts in the handshake)."""
    import os
    import signal
    import struct
    import time
    from pathlib import Path

    from websockets.sync.client import connect

    from conftest import ALPHA
    from helpers import wait_registered
    from nearsub.common.mission.schema import load_mission
    from nearsub.tools.commands.view import start_server_process

    mission = load_mission(ALPHA)
    startup, step = mission.startup_timeout, mission.step_timeout
    launches.start(ALPHA, "--set", f"name={community}", "--warp", "1", "--until", "300")
    entry = wait_registered(community, timeout=2 * startup + step)
    process, url = start_server_process("foxglove", Path(entry["log"]).parent / "run.json", 0, startup)
    try:
        assert url.startswith("ws://127.0.0.1:")
        with connect(url, subprotocols=["foxglove.sdk.v1"], open_timeout=step) as socket:
            assert socket.subprotocol == "foxglove.sdk.v1"
            channels, pose, subscribed, deadline = {}, None, False, time.monotonic() + startup
            while pose is None:
                assert time.monotonic() < deadline, f"no pose within {startup:g} s; channels {sorted(channels)}"
                frame = socket.recv(timeout=step)
                if isinstance(frame, str):
                    message = json.loads(frame)
                    for channel in message.get("channels", []) if message["op"] == "advertise" else []:
                        channels[channel["topic"]] = channel
                    # A subscription sent right after the advertisement can reach the server before
                    # it knows the channel ("Unknown channel ID" status): ask again after each message.
                    if "/tf" in channels and not subscribed:
                        socket.send(json.dumps({"op": "subscribe", "subscriptions": [
                            {"id": 7, "channelId": channels["/tf"]["id"]}]}))  # fmt: skip
                        subscribed = True
                    if message["op"] == "status" and "Unknown channel" in message["message"]:
                        subscribed = False
                elif frame[0] == 1:  # message data: op, subscription id, log time, payload
                    subscription, log_time = struct.unpack_from("<IQ", frame, 1)
                    assert subscription == 7
                    pose = json.loads(frame[13:])
        assert channels["/tf"]["schemaName"] == "foxglove.FrameTransform" and channels["/tf"]["encoding"] == "json"
        assert channels[f"nearsub/{community}/remus100/state"]["schemaName"] == "nearsub.State"
        assert pose["child_frame_id"] == "remus100" and pose["parent_frame_id"] == "world"
        assert abs(log_time / 1e9 - time.time()) < 3600  # on the wall-clock epoch
    finally:
        os.killpg(process.pid, signal.SIGTERM)
        process.wait(timeout=step)


def companion_urls(process, count: int, timeout: float) -> dict[str, str]:
    """{tool: URL} of the first `count` servers a `nearsub launch` prints (`TOOL at URL`)."""
    import queue
    import threading
    import time

    lines: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in process.stderr], daemon=True).start()
    urls, deadline = {}, time.monotonic() + timeout
    while len(urls) < count:
        line = lines.get(timeout=max(0.1, deadline - time.monotonic()))
        if line.startswith("nearsub launch: ") and " at " in line:
            tool, url = line.removeprefix("nearsub launch: ").strip().split(" at ", 1)
            urls[tool] = url.split()[0]  # the viewer: its control URL first
    return urls


def test_launch_foxglove_takes_a_free_loopback_port_by_default(launches, community):
    """Foxglove's own port 8765 taken (by another mission's server, say): a launch still serves."""
    import socket as sockets

    from websockets.sync.client import connect

    from conftest import ALPHA
    from nearsub.common.mission.schema import load_mission

    mission = load_mission(ALPHA)
    holder = sockets.socket()
    try:
        holder.bind(("127.0.0.1", 8765))
        holder.listen()
    except OSError:
        pass  # someone else holds it already: the case itself
    try:
        process = launches.start(ALPHA, "--set", f"name={community}", "--until", "20", "--warp", "2", "--foxglove")
        url = companion_urls(process, 1, timeout=3 * mission.startup_timeout)["foxglove"]
        host, port = url.removeprefix("ws://").split(":")
        assert host == "127.0.0.1" and int(port) != 8765
        with connect(url, subprotocols=["foxglove.sdk.v1"], open_timeout=mission.step_timeout) as socket:
            info = json.loads(socket.recv(timeout=mission.step_timeout))
        assert info["op"] == "serverInfo" and info["capabilities"] == []  # nothing a client could drive
        process.wait(timeout=20 / 2 + 3 * mission.startup_timeout)
        assert process.returncode == 0
    finally:
        holder.close()


def test_launch_view_and_foxglove_serve_while_the_mission_runs_and_stop_with_it(launches, community):
    import socket as sockets
    import urllib.request

    from websockets.sync.client import connect

    from conftest import ALPHA
    from nearsub.common.mission.schema import load_mission

    mission = load_mission(ALPHA)
    startup, step = mission.startup_timeout, mission.step_timeout
    process = launches.start(
        ALPHA,
        "--set",
        f"name={community}",
        "--warp",
        "2",
        "--until",
        "20",
        "--view",
        "--foxglove",
        "--foxglove-port",
        "0",
    )
    urls = companion_urls(process, 2, timeout=3 * startup)
    with urllib.request.urlopen(urls["view"], timeout=step) as page:
        assert b"viewer.js" in page.read()
    with connect(urls["foxglove"], subprotocols=["foxglove.sdk.v1"], open_timeout=step) as socket:
        assert json.loads(socket.recv(timeout=step))["op"] == "serverInfo"
    process.wait(timeout=20 / 2 + 3 * startup)
    assert process.returncode == 0
    for url in urls.values():  # stopped with the mission
        host, port = url.split("//")[1].split("/")[0].split(":")
        with pytest.raises(ConnectionRefusedError):
            sockets.create_connection((host, int(port)), timeout=step).close()


def test_foxglove_bad_input_is_one_line_and_exit_2(runtime_dir, tmp_path):
    for argv, words in ((["nosuchmission"], "no running mission named"),
                        (["alpha", "--run", str(tmp_path / "run.json")], "not a readable run file")):  # fmt: skip
        out = nearsub("foxglove", *argv)
        assert out.returncode == 2 and words in out.stderr and len(out.stderr.strip().splitlines()) == 1, out.stderr
    out = nearsub("foxglove", "alpha", "--port", "70000")  # argparse: its usage, then the option and value
    assert out.returncode == 2 and "argument --port: wants a whole number >= 0 and <= 65535, got '70000'" in out.stderr
