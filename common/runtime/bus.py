"""The only module that talks to Zenoh (eclipse-zenoh 1.10; docs/design.md, "Transport").

Rules it enforces for every app:
- sessions open in `with` blocks, listen on explicit loopback endpoints, multicast scouting off;
- lock-step and log traffic uses `CongestionControl.BLOCK` publishers (the default DROP loses
  messages under load: `CongestionControl.DEFAULT` is DROP in zenoh/__init__.pyi);
- apps receive through Zenoh FIFO channels drained by their own main loop (`Stream`); nothing
  blocks or calls Zenoh inside a callback.

Why a `Stream` holds exactly the keys an app consumes (docs/design.md, "Transport"): Zenoh key
expressions have no alternation and a FifoChannel cannot be waited on together with another, so
one wide FifoChannel on nearsub/<community>/** woke every app for every message (about 2.5 per
step each, most of them filtered out again). A `Stream` is instead fed by one subscription per
key expression the app consumes, each a direct callback (run on Zenoh's receive thread) that
appends the sample to one `queue.SimpleQueue`. Zenoh dispatches one link's samples on one thread
in arrival order, so the queue keeps the order of a single subscription across keys; it never
drops a sample. The key expressions must not overlap (a sample matching two would be queued
twice). The logger, which sees everything, keeps one FifoChannel (`Bus.stream`); apps use `Bus.inputs`. Deadlines use
SIGALRM (`deadline`), which interrupts a blocked `recv` at once.

The launcher and the tools, which see little traffic, use a `Mailbox`: direct callbacks that
append to a `queue.SimpleQueue`, which allows timeouts and mixes samples, queries and liveliness.

How the apps link (`app_link`, docs/architecture.md, "Links"): on a router of this host every app
is a Zenoh peer listening on a loopback port of its own; the router's gossip gives each the
others' locators and they link pairwise, so a message goes app -> app in one hop. The router's
peers form one subregion in which nobody forwards (Zenoh's regions): a message travels the direct
link or nowhere, so it is never delivered twice, and the router carries only the traffic of its
clients (the launcher, the tools). A peer therefore meets every other peer before it declares its
liveliness token (`Bus.token`): then whoever sees the token can rely on every app knowing the
subscriptions declared before it. On a router elsewhere (`network.connect`, apps maybe on several
hosts, where a loopback locator means nothing) every app is the router's client, as the tools are.
"""

from __future__ import annotations

import functools
import ipaddress
import json
import os
import queue
import signal
import socket
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import zenoh

from . import credentials as mission_credentials
from .endpoints import endpoint_problem, split

ENCODING = "application/msgpack"

# How long a client keeps trying to reach its router before giving up. The launcher sets the
# mission's startup_timeout here for every process it starts; others use the default (the
# mission default), since an app started on a loaded machine may find its router slow to accept.
CONNECT_TIMEOUT_VARIABLE = "NEARSUB_CONNECT_TIMEOUT"
DEFAULT_CONNECT_TIMEOUT = 30.0

# The link of the mission apps (module docstring): "peer" on a router of this host for a mission
# of at most PEER_APPS apps, "client" otherwise. The launcher hands its choice to the apps it
# starts in $NEARSUB_LINK; set by hand to client or peer, that variable decides instead.
LINK_VARIABLE = "NEARSUB_LINK"
LINKS = ("client", "peer")
PEER_LISTEN = "tcp/127.0.0.1:0"  # a peer's own listener: loopback, a free port
# Peers link pairwise and a publisher sends to each subscriber itself, so a fleet's mesh grows
# as the square of its apps and the clock's every tick goes out once per app. Measured with
# `nearsub bench pipeline --vehicles N` as peers against as clients (one run each, load 17-130):
# 2 vehicles 175 against 222 steps/s, 4 about equal, 16 vehicles 4.39 against 3.90 CPU-ms per
# vehicle-step and a start-up of 85 against 53 s. One vehicle's apps (logger, surrogate server,
# sim, pid, helm, clock) gain.
PEER_APPS = 6

# Zenoh's async runtimes in a mission app (read by Zenoh when the process opens its first session;
# RON, Zenoh's `ZRuntime` documentation). By default each process runs the receive, accept,
# network and application runtimes on workers of their own (12-15 threads an app, measured); a
# lock-stepped app handles one message at a time, so the handoffs between those threads were
# most of its CPU. All but the sender run on one worker here. Measured with `nearsub bench
# pipeline --repeats 2` against Zenoh's default, alternating on one 2-core machine: alpha 1090 ->
# 1388-1402 steps/s and 1.27 -> 0.92-0.94 CPU-ms per step; overtake_stern_nuv 340-368 -> 354-492
# steps/s and 3.48-3.80 -> 2.52-3.52 CPU-ms. Handing the sender (tx) over too deadlocked the
# apps. The launcher hands it to the apps it starts, not to its router; a value the user has set
# in ZENOH_RUNTIME is kept.
RUNTIME_VARIABLE = "ZENOH_RUNTIME"
APP_RUNTIME = "(rx: (handover: app), acc: (handover: app), net: (handover: app), app: (worker_threads: 1))"


@contextmanager
def app_runtime() -> Iterator[None]:
    """APP_RUNTIME in this process's environment while the block runs (a user's ZENOH_RUNTIME is
    kept): for the apps started inside it, and for this process's own Zenoh if it opens its first
    session inside it (Zenoh reads the variable once per process)."""
    given = os.environ.get(RUNTIME_VARIABLE)
    os.environ.setdefault(RUNTIME_VARIABLE, APP_RUNTIME)
    try:
        yield
    finally:
        if given is None:
            os.environ.pop(RUNTIME_VARIABLE, None)


class BusError(RuntimeError):
    """A session that could not be opened; the one-line text names the endpoints."""


def connect_timeout() -> float:
    """Seconds a client waits for its router: $NEARSUB_CONNECT_TIMEOUT, else the default."""
    try:
        value = float(os.environ.get(CONNECT_TIMEOUT_VARIABLE, DEFAULT_CONNECT_TIMEOUT))
    except ValueError:
        return DEFAULT_CONNECT_TIMEOUT
    return value if 0 < value < 1e6 else DEFAULT_CONNECT_TIMEOUT


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port that is free right now on `host` (for the launcher's router)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return sock.getsockname()[1]


def check_endpoints(role: str, endpoints: Iterable[str]) -> list[str]:
    """The endpoints a session listens on (`role` "listen") or connects to ("connect"); BusError
    naming the first one that cannot be used (`endpoints.endpoint_problem`, then Zenoh's own
    parse). Zenoh's error names no option and carries its Rust source location, and a client
    takes a port out of range for a router to retry until its timeout (30 s by default)."""
    endpoints = list(endpoints)
    for endpoint in endpoints:
        problem = endpoint_problem(endpoint, listen=role == "listen")
        if problem is None:
            try:
                zenoh.Config().insert_json5(f"{role}/endpoints", json.dumps([endpoint]))
            except zenoh.ZError as exc:
                problem = f"{endpoint!r}: {_reason(exc)}"
        if problem is not None:
            raise BusError(f"{role} endpoint {problem}")
    return endpoints


def key_problem(key: str) -> str | None:
    """Why `key` is not a Zenoh key expression, in Zenoh's words; None when it is one. For tools
    to name a bad key before they subscribe (Zenoh's error there reads like a lost bus)."""
    try:
        zenoh.KeyExpr(key)
    except zenoh.ZError as exc:
        return _reason(exc).rpartition("`: ")[2]
    return None


def is_local(endpoint: str) -> bool:
    """Whether a Zenoh endpoint is on this host: a loopback address, `localhost` or a Unix socket."""
    protocol, address = split(endpoint)
    if protocol.startswith("unix"):
        return True
    host = address.rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # a host name: maybe another host
        return False


def app_link(connect: Iterable[str], apps: int | None = None) -> str:
    """How the `apps` apps of a mission join the router at `connect`: "peer" when it is on this
    host and they are at most PEER_APPS, else "client" (module docstring); $NEARSUB_LINK, when
    "client" or "peer", decides instead."""
    forced = os.environ.get(LINK_VARIABLE, "")
    if forced in LINKS:
        return forced
    connect = list(connect)
    local = bool(connect) and all(is_local(e) for e in connect)
    return "peer" if local and (apps is None or apps <= PEER_APPS) else "client"


def app_environment(
    connect: Iterable[str], apps: int, timeout: float, credentials: str | None, environ: Mapping[str, str] = os.environ
) -> dict[str, str]:
    """The environment of the processes a launcher starts for a mission of `apps` apps on the
    router at `connect`: `environ` (its own) with how long a client keeps trying to reach the
    router (`timeout` seconds), the mission's `credentials` file (None: as `environ` has it), how
    the apps link (`app_link`) and their Zenoh runtime (APP_RUNTIME unless `environ` sets one).
    Handed to each child, so the launcher's own environment stays as it was and a second launch in
    the same process inherits nothing of the first."""
    env = dict(environ)
    env[CONNECT_TIMEOUT_VARIABLE] = f"{timeout:g}"
    if credentials:
        env[mission_credentials.VARIABLE] = credentials
    env[LINK_VARIABLE] = app_link(connect, apps)
    env.setdefault(RUNTIME_VARIABLE, APP_RUNTIME)
    return env


def app_endpoints(connect: Iterable[str]) -> Endpoints:
    """The endpoints of a mission app (clock, logger, surrogate server, sim, pid, helm) whose
    router is at `connect`: a listening peer or a client, as `app_link` says."""
    connect = tuple(connect)
    mode = app_link(connect)
    return Endpoints(mode, connect, listen=(PEER_LISTEN,) if mode == "peer" else ())


def make_config(
    mode: str,
    connect: Iterable[str] = (),
    listen: Iterable[str] = (),
    multicast_scouting: bool = False,
    admin_space: bool = False,
    timeout: float | None = None,
    credentials: str | os.PathLike | None = None,
) -> zenoh.Config:
    """A session configuration; a client or peer waits up to `timeout` seconds (default
    `connect_timeout()`) for its `connect` endpoints, retrying, then fails. With a `credentials`
    file the session authenticates with its user and password, and a router also admits only
    sessions that present them (the file is its dictionary)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(multicast_scouting))
    conf.insert_json5("listen/endpoints", json.dumps(check_endpoints("listen", listen)))
    conf.insert_json5("connect/endpoints", json.dumps(check_endpoints("connect", connect)))
    if mode == "peer":
        # Gossip from the router (one hop) names the other peers; link to each of them, and of
        # two peers only the one with the greater Zenoh id dials, so no pair races two handshakes.
        conf.insert_json5("scouting/gossip/enabled", "true")
        conf.insert_json5("scouting/gossip/multihop", "false")
        conf.insert_json5("scouting/gossip/autoconnect", json.dumps(["router", "peer"]))
        conf.insert_json5(
            "scouting/gossip/autoconnect_strategy", json.dumps({"to_router": "always", "to_peer": "greater-zid"})
        )
        # Its admin space answers `Bus.token`'s round trip in Zenoh itself, without Python.
        admin_space = True
    if mode != "router":
        # Wait for the router instead of failing at once, so start order does not matter.
        seconds = connect_timeout() if timeout is None else timeout
        conf.insert_json5("connect/timeout_ms", json.dumps(int(seconds * 1000)))
        conf.insert_json5("connect/exit_on_failure", json.dumps(True))
    if credentials is not None:
        try:
            found = mission_credentials.load(credentials)
        except mission_credentials.CredentialsError as exc:
            raise BusError(str(exc)) from None
        auth = {"user": found.user, "password": found.password}
        if mode != "client":  # a router's or a peer's listener admits only holders of the file
            auth["dictionary_file"] = str(found.path)
        conf.insert_json5("transport/auth/usrpwd", json.dumps(auth))
    if admin_space:
        conf.insert_json5("adminspace", json.dumps({"enabled": True, "permissions": {"read": True, "write": False}}))
    return conf


@dataclass(frozen=True)
class Endpoints:
    """How an app reaches the others: as a client of a router, or as a listening peer."""

    mode: str = "client"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    multicast_scouting: bool = False
    timeout: float | None = None  # seconds to keep trying `connect`; None: connect_timeout()
    credentials: str | None = None  # the mission's credentials file; None: $NEARSUB_CREDENTIALS

    def config(self) -> zenoh.Config:
        listen = self.listen if self.mode == "peer" else ()
        credentials = self.credentials or mission_credentials.from_environment()
        return make_config(
            self.mode, self.connect, listen, self.multicast_scouting, timeout=self.timeout, credentials=credentials
        )


@dataclass
class Mail:
    """One item in a mailbox. kind: "sample", "query", "alive" or "gone"."""

    kind: str
    key: str
    payload: bytes = b""
    query: Any = None

    def reply(self, payload: bytes) -> None:
        """Answer a query with `payload` and finalise it."""
        with self.query as q:
            q.reply(q.key_expr, payload)

    def reply_error(self, text: str) -> None:
        with self.query as q:
            q.reply_err(text.encode())


class Mailbox:
    """FIFO of everything an app receives, drained by its main loop."""

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue[Mail] = queue.SimpleQueue()

    def get(self, timeout: float | None = None) -> Mail | None:
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def put(self, mail: Mail) -> None:
        self._queue.put(mail)

    def on_sample(self, sample: zenoh.Sample) -> None:
        self._queue.put(Mail("sample", str(sample.key_expr), sample.payload.to_bytes()))

    def on_query(self, query: zenoh.Query) -> None:
        payload = query.payload.to_bytes() if query.payload is not None else b""
        self._queue.put(Mail("query", str(query.key_expr), payload, query))

    def on_liveliness(self, sample: zenoh.Sample) -> None:
        kind = "alive" if sample.kind == zenoh.SampleKind.PUT else "gone"
        self._queue.put(Mail(kind, str(sample.key_expr)))


def _direct(callback) -> zenoh.handlers.Callback:
    # indirect=False runs the callback on Zenoh's receive thread: no extra Python thread hop.
    # The callback only appends to a SimpleQueue, which never blocks.
    return zenoh.handlers.Callback(callback, indirect=False)


class DeadlineExceeded(Exception):
    """Raised in the main thread when a `deadline` expires (e.g. inside a blocked recv)."""


def _raise_deadline(signum, frame):
    raise DeadlineExceeded()


@contextmanager
def deadline(seconds: float):
    """Raise DeadlineExceeded if the block takes longer than `seconds` of wall time (main thread
    only; uses SIGALRM, so blocked Zenoh receives are interrupted)."""
    previous = signal.signal(signal.SIGALRM, _raise_deadline)
    signal.setitimer(signal.ITIMER_REAL, max(seconds, 1e-6))
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


class Stream:
    """Samples of one or more subscriptions in arrival order, drained by the app's main loop:
    yields (key, payload). See the module docstring for why and how order is kept."""

    def __init__(self, handler=None):
        self._handler = handler
        self._queue: queue.SimpleQueue[zenoh.Sample] = queue.SimpleQueue()

    def put(self, sample: zenoh.Sample) -> None:
        """The subscription callback: queue the sample, nothing else (Zenoh's receive thread)."""
        self._queue.put(sample)

    def recv(self) -> tuple[str, bytes]:
        sample = self._handler.recv() if self._handler is not None else self._queue.get()
        return str(sample.key_expr), sample.payload.to_bytes()

    def try_recv(self, timeout: float = 0.0) -> tuple[str, bytes] | None:
        """The next sample, waiting up to `timeout` seconds for one (`inputs` streams only)."""
        if self._handler is not None:
            sample = self._handler.try_recv()
        else:
            try:
                sample = self._queue.get(timeout=timeout) if timeout > 0 else self._queue.get_nowait()
            except queue.Empty:
                sample = None
        if sample is None:
            return None
        return str(sample.key_expr), sample.payload.to_bytes()


class Request:
    """A received query (`query` set: answer it exactly once with `reply` or `reply_error`), or a
    published request (`query` None: the server publishes its answer itself): key and payload."""

    __slots__ = ("query", "key", "payload")

    def __init__(self, key: str, payload: bytes, query: zenoh.Query | None = None):
        self.query, self.key, self.payload = query, key, payload

    def reply(self, payload: bytes) -> None:
        with self.query as q:
            q.reply(q.key_expr, payload, encoding=ENCODING)

    def reply_error(self, text: str) -> None:
        with self.query as q:
            q.reply_err(text.encode())


class RequestStream:
    """Queries to one queryable and requests published under one key, in one FIFO in arrival
    order, drained by the serving app's main loop (the callbacks only append, on Zenoh's thread)."""

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue[Request] = queue.SimpleQueue()

    def on_query(self, query: zenoh.Query) -> None:
        payload = query.payload.to_bytes() if query.payload is not None else b""
        self._queue.put(Request(str(query.key_expr), payload, query))

    def on_sample(self, sample: zenoh.Sample) -> None:
        self._queue.put(Request(str(sample.key_expr), sample.payload.to_bytes()))

    def recv(self) -> Request:
        return self._queue.get()


class ReplyError(RuntimeError):
    """A query that got no answer, or an error answer; the text says which and from where."""


class PendingReply:
    """A query sent and not yet answered: `result` waits for the first reply (the asker works
    meanwhile; the replies queue in Zenoh's channel without this thread)."""

    __slots__ = ("_replies", "_key", "_timeout")

    def __init__(self, replies, key: str, timeout: float):
        self._replies, self._key, self._timeout = replies, key, timeout

    def result(self) -> bytes:
        """The first reply's payload; ReplyError when nobody answers or the answer is an error."""
        for reply in self._replies:
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
            raise ReplyError(f"{self._key}: {reply.err.payload.to_bytes().decode(errors='replace')}")
        raise ReplyError(f"{self._key}: no reply within {self._timeout:g} s (is the server running?)")


class Requester:
    """Requests published on keys and their replies, published by the server on this requester's
    own `reply_key`: a pub/sub pair, cheaper than a get's round trip (`nearsub bench surrogate`
    times both). The server's liveliness tokens (`server`) are watched, so a wait for a reply ends
    as soon as the last of them goes (the server died) instead of at the timeout. The caller
    matches replies to requests (the payloads carry its numbers)."""

    _GONE = None  # queued when the last server token goes

    def __init__(self, session: zenoh.Session, keep: list, reply_key: str, server: str, timeout: float):
        self.reply_key, self.server, self.timeout = reply_key, server, timeout
        self._queue: queue.SimpleQueue[bytes | None] = queue.SimpleQueue()
        self._session, self._keep = session, keep
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._servers: set[str] = set()
        self.gone = False  # a server was seen and none is left
        # Subscribed before any request goes out, so the server knows the reply key when it
        # answers (`Bus.put_reply`).
        keep.append(session.declare_subscriber(reply_key, _direct(self._on_reply)))
        keep.append(session.liveliness().declare_subscriber(server, _direct(self._on_server), history=True))

    def _on_reply(self, sample: zenoh.Sample) -> None:
        self._queue.put(sample.payload.to_bytes())

    def _on_server(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self._servers.add(str(sample.key_expr))
            self.gone = False
        else:
            self._servers.discard(str(sample.key_expr))
            if not self._servers:
                self.gone = True
                self._queue.put(self._GONE)

    def _gone_error(self) -> ReplyError:
        return ReplyError(f"{self.server}: the server's liveliness token is gone (it stopped or died)")

    def send(self, key: str, payload: bytes) -> float:
        """Publish a request on `key`; returns the deadline (monotonic seconds) of its reply. The
        first request on a key waits, up to the timeout, until the server's subscription is known
        here (data put before that is not delivered)."""
        if self.gone:
            raise self._gone_error()
        publisher = self._publishers.get(key)
        if publisher is None:
            publisher = self._session.declare_publisher(
                key, encoding=ENCODING, congestion_control=zenoh.CongestionControl.BLOCK, express=True
            )
            self._keep.append(publisher)
            end = time.monotonic() + self.timeout
            while not publisher.matching_status.matching:
                if time.monotonic() > end:
                    raise ReplyError(f"{key}: no server subscribed within {self.timeout:g} s (is it running?)")
                time.sleep(0.002)
            self._publishers[key] = publisher
        publisher.put(payload)
        return time.monotonic() + self.timeout

    def reply(self, deadline: float) -> bytes:
        """The next reply's payload; ReplyError at the deadline, or once the server is gone."""
        while True:
            try:
                payload = self._queue.get(timeout=max(deadline - time.monotonic(), 0.0))
            except queue.Empty:
                raise ReplyError(
                    f"{self.reply_key}: no reply within {self.timeout:g} s (is the server running?)"
                ) from None
            if payload is not self._GONE:
                return payload
            if self.gone:  # (not a server that has come back since)
                raise self._gone_error()


class Querier:
    """Repeated queries to one key (a tool asking the surrogate server)."""

    def __init__(self, querier, key: str, timeout: float):
        self._querier = querier
        self.key = key
        self.timeout = timeout

    def send(self, payload: bytes) -> PendingReply:
        """Send a query now and take its reply later (`PendingReply.result`)."""
        return PendingReply(self._querier.get(payload=payload), self.key, self.timeout)

    def ask(self, payload: bytes) -> bytes:
        """The first reply's payload; ReplyError when nobody answers or the answer is an error."""
        return self.send(payload).result()


def queue_lost(lost: queue.SimpleQueue) -> Callable[[Any], None]:
    """A liveliness callback that queues the key of each token that goes away (an app that left
    or died), for the main thread to read."""

    def on_sample(sample) -> None:
        if sample.kind == zenoh.SampleKind.DELETE:
            lost.put(str(sample.key_expr))

    return on_sample


def signal_self(signum: int = signal.SIGTERM) -> Callable[[Any], None]:
    """A liveliness callback that asks this process to shut down (non-blocking, no Zenoh call);
    the signal interrupts a blocked `Stream.recv` in the main thread."""

    def on_sample(sample) -> None:
        if sample.kind == zenoh.SampleKind.DELETE:
            os.kill(os.getpid(), signum)

    return on_sample


class Publisher:
    def __init__(self, publisher: zenoh.Publisher):
        self._publisher = publisher

    def put(self, payload: bytes) -> None:
        self._publisher.put(payload)


def _reason(exc: Exception) -> str:
    """Zenoh's first line, without the Rust source location it appends ("... at /root/...rs:388.")."""
    reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return reason.split(" at /", 1)[0].rstrip(".")


def open_error(config: zenoh.Config, exc: Exception) -> str:
    """One line for a session that did not open: the endpoints and Zenoh's reason."""

    def read(key: str):
        try:
            return json.loads(config.get_json(key))
        except Exception:  # a key this Zenoh does not know: say less
            return None

    connect = read("connect/endpoints") or []
    if isinstance(connect, dict):  # per-mode form {"router": [...], "peer": [...], "client": [...]}
        connect = [e for v in connect.values() for e in v]
    reason = _reason(exc)
    if "Timeout" in reason and connect:
        timeout_ms = read("connect/timeout_ms")
        within = f" within {timeout_ms / 1000:g} s" if isinstance(timeout_ms, int | float) else ""
        # A router refusing the credentials (or their absence) looks the same as no router.
        user = read("transport/auth/usrpwd/user")
        hint = f"does it accept user {user}?" if user else "does it require credentials?"
        return f"cannot reach {', '.join(connect)}{within} (is the router running there, and {hint})"
    listen = read("listen/endpoints") or []
    where = ", ".join(connect) or (", ".join(listen) if isinstance(listen, list) else str(listen))
    return f"cannot open a Zenoh session on {where or 'no endpoint'}: {reason}"


def _router_lost(method):
    """A Zenoh error inside `method` (the router vanished mid-command) as a BusError naming the
    endpoints, which the command line prints as one line."""

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except zenoh.ZError as exc:
            raise BusError(f"lost the bus at {self.where()}: {_reason(exc)}") from None

    return wrapper


class Bus:
    """A Zenoh session with the few operations nearsub needs. Use as a context manager."""

    def __init__(self, endpoints: Endpoints | zenoh.Config):
        self._config = endpoints.config() if isinstance(endpoints, Endpoints) else endpoints
        self._session: zenoh.Session | None = None
        self._keep: list[Any] = []
        self._peer = json.loads(self._config.get_json("mode")) == "peer"
        timeout = endpoints.timeout if isinstance(endpoints, Endpoints) else None
        self._meet_timeout = connect_timeout() if timeout is None else timeout

    def __enter__(self) -> Bus:
        try:
            self._session = zenoh.open(self._config)
        except zenoh.ZError as exc:
            raise BusError(open_error(self._config, exc)) from None
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._session is not None:
            for entity in reversed(self._keep):
                try:
                    entity.undeclare()
                except Exception:  # already gone with the session; nothing to undo
                    pass
            self._keep.clear()
            self._session.close()
            self._session = None

    @property
    def session(self) -> zenoh.Session:
        return self._session

    def where(self) -> str:
        """The endpoints this session connects to, for messages."""
        try:
            connect = json.loads(self._config.get_json("connect/endpoints"))
        except Exception:  # a config this Zenoh cannot read back: say less
            connect = []
        return ", ".join(connect) if isinstance(connect, list) and connect else "its endpoint"

    def publisher(self, key: str, lossless: bool = True) -> Publisher:
        congestion = zenoh.CongestionControl.BLOCK if lossless else zenoh.CongestionControl.DROP
        pub = self._session.declare_publisher(key, encoding=ENCODING, congestion_control=congestion, express=True)
        self._keep.append(pub)
        return Publisher(pub)

    @_router_lost
    def put(self, key: str, payload: bytes) -> None:
        """One-off lossless publication (tools, rare events)."""
        self._session.put(key, payload, encoding=ENCODING, congestion_control=zenoh.CongestionControl.BLOCK)

    @_router_lost
    def put_when_matched(self, key: str, payload: bytes, wait: float = 2.0) -> bool:
        """Publish once some subscriber matches `key` (a fresh session may not yet know the
        subscribers, and data put before that is not delivered). Returns whether a match was seen;
        publishes anyway after `wait` seconds."""
        pub = self._session.declare_publisher(key, encoding=ENCODING, congestion_control=zenoh.CongestionControl.BLOCK)
        try:
            end = time.monotonic() + wait
            # `matching_status` is an object (always truthy); its answer is `.matching`.
            while not (matched := pub.matching_status.matching) and time.monotonic() < end:
                time.sleep(0.005)
            pub.put(payload)
            return matched
        finally:
            pub.undeclare()

    def put_reply(self, key: str, payload: bytes) -> None:
        """Answer a request on the requester's reply key at once, never waiting for a match: the
        requester subscribed to that key before it sent the request, and the subscription came
        the way the request did, before it (one link, in order: straight from a peer, or from
        the router, which declares its clients' subscriptions to its peers), so this session
        knows it. A requester that left meanwhile costs nothing."""
        self.put(key, payload)

    def stream(self, key: str, capacity: int = 8192, lossy: bool = False) -> Stream:
        """One FIFO-channel subscription (the logger's view of everything). Lossless
        (back-pressure) by default; `lossy` keeps only the newest `capacity` samples, for displays
        that must never slow the mission down."""
        handler = zenoh.handlers.RingChannel(capacity) if lossy else zenoh.handlers.FifoChannel(capacity)
        sub = self._session.declare_subscriber(key, handler)
        self._keep.append(sub)
        return Stream(sub.handler)

    def inputs(self, keys: Iterable[str]) -> Stream:
        """One ordered, lossless stream of the samples under `keys` (non-overlapping key
        expressions), and nothing else."""
        stream = Stream()
        for key in keys:
            self._keep.append(self._session.declare_subscriber(key, _direct(stream.put)))
        return stream

    def on_liveliness_lost(self, key: str, callback: Callable[[Any], None]) -> None:
        """Call `callback(sample)` (from Zenoh's thread) on liveliness changes under `key`."""
        sub = self._session.liveliness().declare_subscriber(key, _direct(callback), history=False)
        self._keep.append(sub)

    @_router_lost
    def subscribe(self, key: str, mailbox: Mailbox) -> None:
        self._keep.append(self._session.declare_subscriber(key, _direct(mailbox.on_sample)))

    def serve(self, key: str, requests: str | None = None) -> RequestStream:
        """A queryable on `key`, and a subscription to the requests published under `requests`,
        whose items queue in one FIFO for the main loop (a server app)."""
        stream = RequestStream()
        self._keep.append(self._session.declare_queryable(key, _direct(stream.on_query)))
        if requests is not None:
            self._keep.append(self._session.declare_subscriber(requests, _direct(stream.on_sample)))
        return stream

    def requester(self, reply_key: str, server: str, timeout: float = 2.0) -> Requester:
        """Requests published to a server whose liveliness tokens are `server`, answered on
        `reply_key` (`Requester`)."""
        return Requester(self._session, self._keep, reply_key, server, timeout)

    def querier(self, key: str, timeout: float = 2.0) -> Querier:
        """A pre-declared querier (cheaper than `request` when asking the same key repeatedly)."""
        querier = self._session.declare_querier(
            key, timeout=timeout, congestion_control=zenoh.CongestionControl.BLOCK, express=True
        )
        self._keep.append(querier)
        return Querier(querier, key, timeout)

    def queryable(self, key: str, mailbox: Mailbox) -> None:
        self._keep.append(self._session.declare_queryable(key, _direct(mailbox.on_query)))

    def token(self, key: str) -> None:
        """Declare a liveliness token; a peer first meets the other peers (`join`)."""
        self.join()
        self._keep.append(self._session.liveliness().declare_token(key))

    def router_peers(self) -> set[str]:
        """Zenoh ids of the peers the router knows now, from its admin space (empty if it has none)."""
        found = set()
        for router in self._session.info.routers_zid():
            for reply in self._session.get(f"@/{router}/router", timeout=self._meet_timeout):
                if reply.ok is not None:
                    sessions = json.loads(reply.ok.payload.to_bytes()).get("sessions", [])
                    found |= {s["peer"] for s in sessions if s.get("whatami") == "peer"}
        return found

    def linked_peers(self) -> set[str]:
        """Zenoh ids of the peers this session has a direct link to."""
        return {str(zid) for zid in self._session.info.peers_zid()}

    def join(self) -> None:
        """A peer meets the other peers (`meet_peers`), so that what it publishes next reaches each
        of them and their answers reach it; a client's router knows them already. A swapped-in app
        joins before it asks its predecessor for the handover: `put_when_matched` is satisfied by any
        subscriber, the logger's included, and a peer not yet met would not get the request."""
        if self._peer:
            self.meet_peers()

    def meet_peers(self) -> None:
        """Link to every peer the router knows, then make a round trip to each linked peer (its
        admin space answers, in Zenoh). A link carries its messages in order and declarations
        outrank queries, so once every answer is in, each of those peers has taken this
        session's declarations and this session has taken theirs. A peer that joins later
        meets this one the same way. Gives up waiting after the connect timeout (a peer that
        never links is a mission that stalls, which the clock reports)."""
        end = time.monotonic() + self._meet_timeout
        wanted = self.router_peers() - {str(self._session.zid())}
        checked = time.monotonic()
        while not wanted <= self.linked_peers() and time.monotonic() < end:
            time.sleep(0.005)
            if time.monotonic() - checked > 0.1:  # a peer that left meanwhile (a swapped-out app) is not waited for
                wanted &= self.router_peers()
                checked = time.monotonic()
        left = max(end - time.monotonic(), 0.1)
        for _ in self._session.get("@/*/peer", target=zenoh.QueryTarget.ALL, timeout=left):
            pass

    def watch_liveliness(self, key: str, mailbox: Mailbox, history: bool = True) -> None:
        sub = self._session.liveliness().declare_subscriber(key, _direct(mailbox.on_liveliness), history=history)
        self._keep.append(sub)

    @_router_lost
    def alive(self, key: str, timeout: float = 1.0) -> list[str]:
        """Keys of the liveliness tokens alive now under `key`."""
        replies = self._session.liveliness().get(key, timeout=timeout)
        return sorted(str(r.ok.key_expr) for r in replies if r.ok is not None)

    @_router_lost
    def request(self, key: str, payload: bytes = b"", timeout: float = 5.0) -> list[tuple[bool, bytes]]:
        """Query `key`; each reply is (ok, payload). No replier gives an empty list."""
        replies = self._session.get(key, payload=payload, timeout=timeout)
        out = []
        for reply in replies:
            if reply.ok is not None:
                out.append((True, reply.ok.payload.to_bytes()))
            else:
                out.append((False, reply.err.payload.to_bytes()))
        return out

    def locators(self, timeout: float = 2.0) -> list[str]:
        """The endpoints this router session actually listens on, read from its own admin space
        (`make_config(..., admin_space=True)`): a listener on port 0 reads back its real port."""
        zid = str(self._session.zid())
        for reply in self._session.get(f"@/{zid}/router", timeout=timeout):
            if reply.ok is not None:
                return list(json.loads(reply.ok.payload.to_bytes()).get("locators", []))
        return []

    @_router_lost
    def admin_keys(self, what: str, timeout: float = 1.0) -> list[str]:
        """Declared entities known to routers (`what` = publisher, subscriber or queryable)."""
        keys = set()
        for reply in self._session.get(f"@/*/router/{what}/**", timeout=timeout):
            if reply.ok is not None:
                key = str(reply.ok.key_expr)
                keys.add(key.split(f"/router/{what}/", 1)[-1])
        return sorted(keys)
