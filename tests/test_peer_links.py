"""The apps of a mission on a router of this host link peer to peer (common/runtime/bus.py,
"How the apps link"): one hop per message, each message delivered once and in order, the
router's clients (launcher, tools) still served, and a peer's own listener as closed to strangers
as the router is."""

from __future__ import annotations

import json
import os

import pytest

from conftest import ALPHA, nearsub
from helpers import finish, wait_registered, wait_until
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime import credentials, keys
from nearsub.common.runtime.bus import (
    LINK_VARIABLE,
    PEER_APPS,
    PEER_LISTEN,
    Bus,
    BusError,
    Endpoints,
    Mailbox,
    app_endpoints,
    app_link,
    free_tcp_port,
    is_local,
    make_config,
)

pytestmark = pytest.mark.timeout(180)

WAIT = 30.0  # seconds for anything that should take milliseconds, on a loaded machine


def peer(endpoint: str, **kwargs) -> Bus:
    return Bus(Endpoints("peer", (endpoint,), listen=(PEER_LISTEN,), **kwargs))


def receive(mailbox: Mailbox, count: int) -> list[bytes]:
    got = []
    while len(got) < count and (mail := mailbox.get(timeout=WAIT)) is not None:
        got.append(mail.payload)
    return got


def test_apps_on_a_router_of_this_host_are_peers_and_elsewhere_clients(monkeypatch):
    monkeypatch.delenv(LINK_VARIABLE, raising=False)
    for endpoint in ("tcp/127.0.0.1:7447", "tcp/localhost:7447", "tcp/[::1]:7447", "unixsock-stream//tmp/z.sock"):
        assert is_local(endpoint), endpoint
    for endpoint in ("tcp/192.0.2.10:7447", "tcp/[2001:db8::1]:7447", "tcp/router.example:7447"):
        assert not is_local(endpoint), endpoint
    assert app_link(["tcp/127.0.0.1:7447"]) == "peer"
    assert app_link(["tcp/127.0.0.1:7447", "tcp/192.0.2.10:7447"]) == "client"
    assert app_link([]) == "client"
    # A fleet's apps stay clients: a full mesh of its many apps costs more than the hop it saves.
    assert app_link(["tcp/127.0.0.1:7447"], apps=PEER_APPS) == "peer"
    assert app_link(["tcp/127.0.0.1:7447"], apps=PEER_APPS + 1) == "client"
    local = app_endpoints(["tcp/127.0.0.1:7447"])
    assert (local.mode, local.listen) == ("peer", (PEER_LISTEN,))
    assert app_endpoints(["tcp/192.0.2.10:7447"]).mode == "client"
    monkeypatch.setenv(LINK_VARIABLE, "client")
    assert app_link(["tcp/127.0.0.1:7447"]) == "client"
    monkeypatch.setenv(LINK_VARIABLE, "peer")
    assert app_link(["tcp/192.0.2.10:7447"]) == "peer"


def test_peers_link_directly_and_get_each_message_once_in_order():
    """Two peers and a client of their router subscribe to one publisher: each gets every message
    once, in order; and the peers' link is direct: it outlives the router."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    count = 2000
    router = Bus(make_config("router", listen=[endpoint], admin_space=True)).__enter__()
    try:
        with peer(endpoint) as sender, peer(endpoint) as first, peer(endpoint) as second:
            with Bus(Endpoints("client", (endpoint,))) as watcher:
                boxes = [Mailbox() for _ in range(3)]
                for bus, box in zip((first, second, watcher), boxes, strict=True):
                    bus.subscribe("test/data", box)
                    bus.token(f"test/alive/{id(box)}")
                sender.meet_peers()
                assert {first.session.zid(), second.session.zid()} <= set(sender.session.info.peers_zid())
                # The watcher's subscription reaches the sender through the router, possibly after
                # the peers' (direct) ones have satisfied `put_when_matched`: wait until the sender
                # is answered the watcher's token, which the router took, and passed on, after it.
                wait_until(
                    lambda: len(sender.alive("test/alive/*")) == len(boxes),
                    WAIT,
                    "the sender did not see every subscriber's token",
                )
                publisher = sender.publisher("test/data")
                assert sender.put_when_matched("test/data", b"first", wait=WAIT)
                for i in range(count):
                    publisher.put(str(i).encode())
                expected = [b"first", *(str(i).encode() for i in range(count))]
                for box in boxes:
                    assert receive(box, count + 1) == expected
                    assert box.get(timeout=0.5) is None  # and nothing twice

            router.close()
            for i in range(100):
                publisher.put(f"after {i}".encode())
            after = [f"after {i}".encode() for i in range(100)]
            assert receive(boxes[0], 100) == after and receive(boxes[1], 100) == after
    finally:
        router.close()


def test_whoever_sees_a_peers_token_can_send_to_it_at_once():
    """The clock's case: a third peer sees the newcomer's token and at once has a second peer
    publish to the newcomer, which must get it (it declared its subscription before its token)."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    with Bus(make_config("router", listen=[endpoint], admin_space=True)), peer(endpoint) as clock:
        with peer(endpoint) as sender:
            tokens = Mailbox()
            clock.watch_liveliness("test/alive/*", tokens, history=False)
            for round_ in range(10):
                with peer(endpoint) as newcomer:
                    box = Mailbox()
                    newcomer.subscribe(f"test/round/{round_}", box)
                    newcomer.token(f"test/alive/{round_}")
                    while (mail := tokens.get(timeout=WAIT)) is not None and mail.kind != "alive":
                        pass
                    assert mail is not None and mail.key == f"test/alive/{round_}"
                    sender.put(f"test/round/{round_}", b"go")
                    got = box.get(timeout=WAIT)
                    assert got is not None and got.payload == b"go", round_


def test_a_newcomer_that_joins_reaches_a_peer_it_has_not_met_and_hears_its_answer():
    """The swap's case: a swapped-in app asks its predecessor for the handover before it declares
    its token. The logger's catch-all subscription satisfies `put_when_matched` as soon as the
    newcomer has linked to the logger, which may be before it has linked to the predecessor, so it
    must join the peers first (`Bus.join`), or the predecessor may never get the request (without
    it, half of the runs of these 40 rounds failed here)."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    with Bus(make_config("router", listen=[endpoint], admin_space=True)), peer(endpoint) as logger:
        logger.subscribe("test/**", Mailbox())
        logger.token("test/alive/logger")
        with peer(endpoint) as predecessor:
            requests = Mailbox()
            predecessor.subscribe("test/control/old", requests)
            predecessor.token("test/alive/old")
            for round_ in range(40):
                with peer(endpoint) as newcomer:
                    replies = Mailbox()
                    newcomer.subscribe(f"test/reply/{round_}", replies)
                    newcomer.join()
                    newcomer.put_when_matched("test/control/old", str(round_).encode(), wait=WAIT)
                    got = requests.get(timeout=WAIT)
                    assert got is not None and got.payload == str(round_).encode(), round_
                    predecessor.put_reply(f"test/reply/{round_}", b"handover")
                    answer = replies.get(timeout=WAIT)
                    assert answer is not None and answer.payload == b"handover", round_


def test_a_peers_own_listener_admits_only_holders_of_the_credentials(tmp_path, monkeypatch):
    monkeypatch.delenv(credentials.VARIABLE, raising=False)
    secret = credentials.create(tmp_path / "mission.credentials")
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = make_config("router", listen=[endpoint], admin_space=True, credentials=secret.path)
    with Bus(router), peer(endpoint, credentials=str(secret.path)) as app:
        zid = app.session.zid()
        info = next(r.ok for r in app.session.get(f"@/{zid}/peer", timeout=WAIT) if r.ok is not None)
        listener = json.loads(info.payload.to_bytes())["locators"]
        assert listener and all(is_local(locator) for locator in listener)
        wrong = tmp_path / "wrong"
        wrong.write_text(f"{secret.user}:not-the-password\n")
        os.chmod(wrong, 0o600)
        for given in (None, str(wrong)):
            with pytest.raises(BusError, match="cannot reach"):
                with Bus(Endpoints("client", tuple(listener), timeout=2.0, credentials=given)):
                    pass
        with Bus(Endpoints("client", tuple(listener), timeout=WAIT, credentials=str(secret.path))) as own:
            assert str(zid) in {str(z) for z in own.session.info.peers_zid()}


def test_a_local_missions_apps_link_each_to_every_other(launches, community):
    settings = [f"name={community}", "pause_at_step=100", "time_limit=10"]
    mission = load_mission(ALPHA, settings)
    process = launches.start(ALPHA, *[a for s in settings for a in ("--set", s)])
    entry = wait_registered(community, timeout=5 * mission.startup_timeout)
    with Bus(Endpoints("client", tuple(entry["connect"]), credentials=entry["credentials"])) as bus:
        apps = bus.alive(keys.all_alive(community), timeout=WAIT)
        assert len(apps) == 6, apps  # logger, sim, pid, helm, clock and the launcher
        peers = {}
        for reply in bus.session.get("@/*/peer", timeout=WAIT):
            if reply.ok is not None:
                info = json.loads(reply.ok.payload.to_bytes())
                peers[str(reply.ok.key_expr).split("/")[1]] = {s["peer"]: s["whatami"] for s in info["sessions"]}
        assert len(peers) == 5, peers  # the launcher is the router's client
        for zid, links in peers.items():
            assert sorted(links.values()) == ["peer"] * 4 + ["router"], zid
            assert set(links) - set(peers) == {next(z for z, w in links.items() if w == "router")}
        resumed = nearsub("clock", community, "resume")
        assert resumed.returncode == 0, resumed.stderr
    code, summary, err = finish(process, timeout=5 * mission.startup_timeout + mission.time_limit * 5)
    assert code == 0 and summary["outcome"] == "time_limit", err
