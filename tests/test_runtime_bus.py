"""The bus's request/reply helpers: `put_when_matched` waits for a subscriber, and `put_reply`
(what the clock and the apps answer control requests with) never waits."""

from __future__ import annotations

import time

from nearsub.common.runtime.bus import Bus, Endpoints, Mailbox, free_tcp_port, make_config

WAIT = 1.0


def test_put_when_matched_waits_for_a_subscriber_and_put_reply_never_waits():
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    with Bus(make_config("router", listen=[endpoint])), Bus(Endpoints("client", (endpoint,))) as sender:
        started = time.monotonic()
        assert not sender.put_when_matched("test/nobody", b"x", wait=WAIT)
        assert time.monotonic() - started >= WAIT  # it did wait, for nobody

        started = time.monotonic()
        for _ in range(20):  # a clock answering `status` to requesters that have gone
            sender.put_reply("test/gone", b"x")
        assert time.monotonic() - started < 5 * WAIT  # waiting would take 20 * 2 s

        with Bus(Endpoints("client", (endpoint,))) as requester:
            mailbox = Mailbox()
            requester.subscribe("test/reply", mailbox)
            assert sender.put_when_matched("test/reply", b"first", wait=30.0)
            sender.put_reply("test/reply", b"second")
            got = [mailbox.get(timeout=30.0), mailbox.get(timeout=30.0)]
            assert [m.payload for m in got if m is not None] == [b"first", b"second"]


def test_tools_name_an_unreachable_router_in_one_line_and_exit_2(tmp_path):
    import os
    import subprocess
    import sys

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"  # nothing listens there
    env = dict(os.environ, NEARSUB_CONNECT_TIMEOUT="1", NEARSUB_RUNTIME_DIR=str(tmp_path))
    for argv in (["tap", "list", "alpha"], ["clock", "alpha", "status"], ["swap", "alpha", "helm"], ["view", "alpha"]):
        out = subprocess.run(
            [sys.executable, "-m", "nearsub", *argv, "--connect", endpoint],
            capture_output=True,
            text=True,
            env=env,
            timeout=120,
        )
        assert out.returncode == 2, (argv, out.stderr)
        lines = out.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"nearsub {argv[0]}: cannot reach {endpoint}"), lines


def test_a_zenoh_error_mid_command_is_a_bus_error_naming_the_endpoint():
    import pytest
    import zenoh

    from nearsub.common.runtime.bus import BusError

    class Vanished:  # a session whose router went away: Zenoh raises on the next operation
        def put(self, *args, **kwargs):
            raise zenoh.ZError("Session closed at /root/.cargo/x.rs:1.")

    bus = Bus(Endpoints("client", ("tcp/127.0.0.1:7447",)))
    bus._session = Vanished()
    with pytest.raises(BusError, match=r"^lost the bus at tcp/127.0.0.1:7447: Session closed$"):
        bus.put("test/key", b"x")
