"""The launcher of `nearsub launch`: a mission as separate processes (the pAntler of nearsub).

Start order: router, then logger, surrogate server, sim, pid, helm (of each vehicle of a fleet:
`auv1/sim-1`, ..., docs/architecture.md, "Several vehicles") and clock at once. The router
is started on loopback port 0 and reports the endpoint it really listens on in a ready file; the
lock-stepped apps wait for the logger's and the server's liveliness before they publish, so
nothing is published before the logger listens, and the clock waits for them. Every wait is
bounded by the mission's startup_timeout, and so is every client's connect (on a loaded machine a
process may take seconds just to import). The launcher supervises every process it started, the
router, logger and surrogate server included: one that exits or crashes is reported with the step
within a fraction of a second, the mission is ended (the logger closes its file), and the rest is
stopped. A launch that fails before its logger started leaves no log folder behind. Stopping escalates per
process group: SIGINT, then SIGTERM, then SIGKILL, 5 s apart (ros2 launch's ladder).

It also serves `nearsub swap` (see `swap`): pause the clock at a step boundary, start the new app
instance, let it take over from the old one, retire the old one, resume.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from collections import Counter
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import msgpack

from nearsub.common.mission.schema import (
    Mission,
    MissionError,
    RunConfig,
    apply_overrides,
    mission_from_dict,
)
from nearsub.common.runtime import credentials as mission_credentials
from nearsub.common.runtime import forkserver, keys
from nearsub.common.runtime.bus import (
    CONNECT_TIMEOUT_VARIABLE,
    LINK_VARIABLE,
    Bus,
    BusError,
    Endpoints,
    Mailbox,
    app_link,
    app_runtime,
)
from nearsub.common.runtime.forkserver import ForkServer, ForkServerError, process_cpu
from nearsub.common.runtime.lifecycle import ORDER
from nearsub.common.runtime.messages import (
    Event,
    MessageError,
    MissionEnd,
    decode,
    encode,
    model_for_key,
)
from nearsub.common.runtime.processes import spawn_app, stop

from . import registry
from .caller import Caller

NORMAL_OUTCOMES = ("completed", "time_limit", "collision")
STATUS_INTERVAL = 1.0  # wall seconds between two updates of the terminal status line
EXIT_GRACE = 2.0  # wall seconds to wait for the mission end after an app left with code 0


class LaunchError(RuntimeError):
    """A launch or a mission that cannot go on; `app` names the process at fault, if one is."""

    def __init__(self, text: str, app: str | None = None):
        super().__init__(text)
        self.app = app


class SwapRefused(LaunchError):
    """A swap request that is wrong in itself (the app, the vehicle, a setting): refused before the
    clock pauses, and answered as bad input (`nearsub swap` exits 2)."""


@dataclass
class Child:
    instance: str
    role: str
    process: subprocess.Popen
    output: Path
    retiring: bool = False

    def tail(self, lines: int = 12) -> str:
        try:
            text = self.output.read_text(errors="replace").splitlines()
        except OSError:
            return ""
        return "\n".join(f"    {line}" for line in text[-lines:])


@dataclass
class Summary:
    community: str
    outcome: str = "error"
    reason: str = ""
    steps: int = 0
    sim_time: float = 0.0
    wall_time: float = 0.0
    run_wall_time: float = 0.0
    waypoints_reached: int = 0
    events: Counter = field(default_factory=Counter)
    log: str = ""
    failed_app: str | None = None
    swaps: list[dict] = field(default_factory=list)
    warp: float = 0.0
    startup_time: float = 0.0  # launch until every process is up (the clock grants step 0)
    shutdown_time: float = 0.0  # mission end until every process has gone
    cpu: dict[str, float] = field(default_factory=dict)  # CPU seconds of each process at the end
    vehicles: dict[str, dict] = field(default_factory=dict)  # a fleet: waypoints and events per vehicle

    def record_vehicle_event(self, vehicle: str, kind: str) -> None:
        mine = self.vehicles.get(vehicle)
        if mine is None:  # not a vehicle of the mission (a stray publisher)
            return
        mine["events"][kind] += 1
        if kind == "waypoint":
            mine["waypoints_reached"] += 1

    @property
    def steps_per_second(self) -> float:
        """Lock-stepped steps per wall second from the first tick to the mission end."""
        return self.steps / self.run_wall_time if self.run_wall_time > 0 else 0.0

    @property
    def achieved_warp(self) -> float:
        """Simulated seconds per wall second from the first tick to the mission end."""
        return self.sim_time / self.run_wall_time if self.run_wall_time > 0 else 0.0

    def as_dict(self) -> dict:
        return {
            "community": self.community,
            "outcome": self.outcome,
            "reason": self.reason,
            "steps": self.steps,
            "sim_time": self.sim_time,
            "wall_time": round(self.wall_time, 3),
            "run_wall_time": round(self.run_wall_time, 3),
            "steps_per_second": round(self.steps_per_second, 1),
            "waypoints_reached": self.waypoints_reached,
            "events": dict(self.events),
            "log": self.log,
            "failed_app": self.failed_app,
            "swaps": self.swaps,
            "warp": self.warp,
            "achieved_warp": round(self.achieved_warp, 2),
            "startup_time": round(self.startup_time, 3),
            "shutdown_time": round(self.shutdown_time, 3),
            "cpu": {name: round(seconds, 3) for name, seconds in self.cpu.items()},
            **(
                {"vehicles": {n: v | {"events": dict(v["events"])} for n, v in self.vehicles.items()}}
                if self.vehicles
                else {}
            ),
        }

    def text(self) -> str:
        events = ", ".join(f"{k} {v}" for k, v in sorted(self.events.items())) or "none"
        lines = [
            f"mission {self.community}: {self.outcome}" + (f" ({self.reason})" if self.reason else ""),
            f"  steps {self.steps}, simulated {self.sim_time:.2f} s, wall {self.wall_time:.2f} s "
            f"({self.run_wall_time:.2f} s running, {self.steps_per_second:.0f} steps/s)",
            f"  waypoints reached {self.waypoints_reached}; events: {events}",
            f"  warp {self.warp:g} requested, {self.achieved_warp:.1f} achieved; start-up {self.startup_time:.2f} s, "
            f"shutdown {self.shutdown_time:.2f} s",
        ]
        for name, mine in sorted(self.vehicles.items()):
            events = ", ".join(f"{k} {v}" for k, v in sorted(mine["events"].items())) or "none"
            lines.append(f"    {name}: waypoints reached {mine['waypoints_reached']}; events: {events}")
        if self.swaps:
            lines.append("  swaps: " + "; ".join(f"{s['old']} -> {s['new']} at step {s['step']}" for s in self.swaps))
        if self.log:
            lines.append(f"  log {self.log}")
        return "\n".join(lines)


# What the fork server loads before it forks the apps (common/runtime/forkserver.py): what every
# lock-stepped app, the logger and the clock import at start-up; near a submarine also the
# surrogate server's GP stack and the sim's interaction, the LF's compiled kernels (from numba's
# cache) and its submarine field table (from nearsub's cache), which the sim and the server
# would otherwise each load.
APP_PRELOAD = ("nearsub.apps.shell", "nearsub.apps.logger", "nearsub.apps.clock", "nearsub.common.mission.cores")
SURROGATE_PRELOAD = (
    "nearsub.apps.surrogate",
    "nearsub.apps.services",
    "nearsub.common.surrogate.model",
    "nearsub.common.surrogate.interaction",
    "nearsub.common.hydro.low_fidelity:compile_kernels",
    "nearsub.common.hydro.low_fidelity:submarine_field",
)


def fork_preload(mission: Mission) -> tuple[str, ...]:
    return APP_PRELOAD + (SURROGATE_PRELOAD if mission.needs_surrogate else ())


def spawn_router(
    folder: Path, timeout: float, credentials: Path, interrupted=lambda: False
) -> tuple[subprocess.Popen, list[str]]:
    """Start a router on loopback port 0 (output in `folder`/router.out) that admits only the
    holders of fresh random `credentials` (written there, mode 0600), and wait, up to `timeout`
    wall seconds, for the ready file in which it names the endpoints it listens on. A router that
    exits first, or stays silent, is a LaunchError naming it; `interrupted()` ends the wait."""
    ready, output = folder / "router.json", folder / "router.out"
    mission_credentials.create(credentials)
    argv = ["--listen", "tcp/127.0.0.1:0", "--ready-file", str(ready), "--with-parent"]
    argv += ["--credentials", str(credentials)]
    with open(output, "wb") as out:
        router = spawn_app("router", argv, out)
    deadline = time.monotonic() + timeout
    try:
        while not ready.exists():
            code = router.poll()
            if code is not None:
                lines = output.read_text(errors="replace").strip().splitlines()
                said = f": {lines[-1]}" if lines else ""
                raise LaunchError(f"the router exited with code {code} before listening{said}", app="router")
            if time.monotonic() > deadline:
                raise LaunchError(f"the router did not report its endpoint within {timeout:g} s", app="router")
            if interrupted():
                raise KeyboardInterrupt
            time.sleep(0.02)
        return router, list(json.loads(ready.read_text()))
    except BaseException:
        stop([router], grace=0.0)
        raise


class Launcher:
    def __init__(self, mission: Mission, mission_path: str | None, log_root: str, quiet: bool = False, companions=()):
        self.mission = mission
        # Started with the run file once the apps are up (`launch --view`, `--foxglove`); each
        # returns its process, which is stopped first.
        self.companions = list(companions)
        self.companion_processes: list[subprocess.Popen] = []
        self.mission_path = mission_path
        self.community = mission.name
        self.quiet = quiet
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        self.run_dir = Path(log_root) / f"{self.community}-{stamp}-{os.getpid()}"
        self.children: dict[str, Child] = {}
        self.summary = Summary(self.community, warp=mission.warp)
        for name in mission.vehicle_names if mission.fleet else ():
            self.summary.vehicles[name] = {"waypoints_reached": 0, "events": Counter()}
        self.ended_at: float | None = None
        self.status_line = not quiet and sys.stdout.isatty()
        self.next_status = 0.0
        self.showing_status = False
        self.launched = time.monotonic()
        self.stop_requested: int | None = None
        self.instance_counter = Counter()
        self.router: subprocess.Popen | None = None
        self.forks: ForkServer | None = None  # the apps' pre-imported parent (runtime/forkserver.py)
        self.credentials: str | None = None  # the file the mission's router requires
        self.stopping = False
        self.clock_started = time.monotonic()

    # -- processes ----------------------------------------------------------------------------
    def spawn(self, module: str, instance: str, role: str, extra: list[str] = ()) -> Child:
        output = self.run_dir / f"{instance}.out"  # a fleet vehicle's apps: in its own folder
        output.parent.mkdir(exist_ok=True)
        args = ["--run", str(self.run_file), "--instance", instance, *extra]
        with open(output, "wb") as out:
            process = None
            if self.forks is not None:
                try:
                    process = self.forks.spawn(f"nearsub.apps.{module}", args, out, self.mission.startup_timeout)
                except ForkServerError as exc:
                    self.say(f"{exc}; starting the apps as their own processes")
                    self.forks = None
            if process is None:
                process = spawn_app(module, args, out)
        child = Child(instance, role, process, output)
        self.children[instance] = child
        self.say(f"started {instance} (pid {process.pid})")
        return child

    def say(self, text: str) -> None:
        """A progress line for people (not with --json)."""
        if not self.quiet:
            self.clear_status()
            print(f"[launch {time.monotonic() - self.launched:5.2f} s] {text}", file=sys.stderr, flush=True)

    def next_instance(self, role: str) -> str:
        self.instance_counter[role] += 1
        return f"{role}-{self.instance_counter[role]}"

    def ended(self, instance: str) -> bool:
        """A process that exited with code 0 left after the mission end (an app can end the
        mission at step 0, before the launcher has seen every token): supervise() reads the end."""
        child = self.children.get(instance)
        return child is not None and child.process.poll() == 0

    def wait_alive(self, bus: Bus, wanted: list[tuple[str, str]], timeout: float) -> None:
        """Wait for the liveliness tokens of (role, instance) pairs; fail naming the missing ones."""
        deadline = time.monotonic() + timeout
        while True:
            alive = set(bus.alive(keys.all_alive(self.community), timeout=0.5))
            missing = [
                inst
                for role, inst in wanted
                if keys.alive(self.community, role, inst) not in alive and not self.ended(inst)
            ]
            if not missing:
                return
            for inst in missing:
                child = self.children.get(inst)
                code = None if child is None else child.process.poll()
                # 0: it ended the mission since `missing` was read (a sim refusing its
                # interaction settings at step 0); supervise() reads that end and its reason.
                if code is not None and code != 0:
                    raise LaunchError(
                        f"app {inst} exited with code {child.process.returncode} during start-up\n{child.tail()}", inst
                    )
            if time.monotonic() > deadline:
                raise LaunchError(f"apps did not come up within {timeout:g} s: {', '.join(missing)}")
            if self.stop_requested:
                raise KeyboardInterrupt
            time.sleep(0.02)

    def stop_all(self) -> None:
        """Let apps leave on their own (the lock-stepped ones exit on the mission end), then
        escalate; the surrogate server serves until they have gone (the sim's last step may still
        ask it about the final state, `Iteration.then`); the logger closes its file last."""
        grace = 0.0 if self.router_lost() else 3.0  # without the router the launcher's end reaches no app
        stop(self.companion_processes, grace=0.0)
        stop([c.process for c in self.children.values() if c.role not in ("logger", "surrogate")], grace=grace)
        stop([c.process for c in self.children.values() if c.role == "surrogate"], grace=0.0)
        stop([c.process for c in self.children.values() if c.role == "logger"], grace=5.0 if grace else 0.0)

    # -- the run ------------------------------------------------------------------------------
    def run(self) -> Summary:
        """Start, supervise and stop the mission. Raises registry.NameTaken when a live launcher
        of the same name is on the bus (a mission on a shared router)."""
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.run_file = self.run_dir / "run.json"
        start_wall = self.launched = time.monotonic()
        # Every process started from here keeps trying to reach its router this long.
        os.environ[CONNECT_TIMEOUT_VARIABLE] = f"{self.mission.startup_timeout:g}"
        previous_handlers = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        link_given = os.environ.get(LINK_VARIABLE)
        try:
            self.forks = forkserver.start(fork_preload(self.mission))  # loads while the router starts
            connect = self.start_router()
            if self.router is not None:
                self.say(f"started router (pid {self.router.pid}) on {', '.join(connect)}")
            # How the apps link (bus.app_link), for every app started from here, swaps included.
            os.environ[LINK_VARIABLE] = app_link(connect, self.app_count())
            RunConfig(mission=self.mission, connect=connect, log_dir=str(self.run_dir)).save(self.run_file)
            log_path = self.run_dir / f"{self.community}.mcap"
            endpoints = Endpoints(
                "client", tuple(connect), timeout=self.mission.startup_timeout, credentials=self.credentials
            )
            with Bus(endpoints) as bus:
                self.bus = bus
                self.mailbox = Mailbox()
                c = self.community
                self.claim_on_bus(bus, connect)
                bus.subscribe(keys.all_events(c), self.mailbox)
                bus.subscribe(keys.mission_end(c), self.mailbox)
                bus.queryable(keys.launcher_control(c), self.mailbox)
                self.caller = Caller(bus, c, "launcher")
                bus.watch_liveliness(keys.all_alive(c), self.mailbox, history=False)
                self.event_pub = bus.publisher(keys.events(c, "launcher"))
                self.end_pub = bus.publisher(keys.mission_end(c))
                bus.token(keys.alive(c, "launcher", "launcher"))
                # The apps' Zenoh threads (bus.APP_RUNTIME), for every app started from here, swaps
                # included; the launcher's own session is open already.
                with app_runtime():
                    try:
                        self.start_apps(bus, log_path)
                        self.summary.startup_time = time.monotonic() - start_wall
                        self.say(
                            f"mission {c} running: {len(self.children) + (self.router is not None)} processes up "
                            f"in {self.summary.startup_time:.2f} s"
                        )
                        names = self.mission.vehicle_names if self.mission.fleet else []
                        # Tools find the mission in the registry.
                        registry.register(self.community, connect, str(log_path), self.credentials, names)
                        self.companion_processes += [start(self.run_file) for start in self.companions]
                        if self.status_line:
                            self.positions: dict[str, tuple] = {}
                            vehicles = self.mission.vehicle_names
                            self.latest_state = bus.stream(keys.vehicle_topic(c, "*", "state"), len(vehicles), True)
                        self.supervise()
                    except LaunchError as exc:
                        self.fail(exc)
                    except KeyboardInterrupt:
                        self.abort("interrupted", "stopped by the user")
                    self.stopping = True
                    self.stop_all()
                    self.drain_mailbox()
        except (BusError, LaunchError) as exc:  # before any app started: there is no mission to end
            self.summary.outcome, self.summary.reason = "error", str(exc).splitlines()[0]
            self.summary.failed_app = getattr(exc, "app", None)
            print(f"nearsub launch: {exc}", file=sys.stderr, flush=True)
        except KeyboardInterrupt:
            self.summary.outcome, self.summary.reason = "interrupted", "stopped by the user"
        finally:
            self.stopping = True
            for signum, handler in previous_handlers.items():
                signal.signal(signum, handler)
            if link_given is None:  # the next launch in this process chooses afresh
                os.environ.pop(LINK_VARIABLE, None)
            else:
                os.environ[LINK_VARIABLE] = link_given
            self.stop_all()
            if self.router is not None:
                stop([self.router], grace=0.0)
            if self.forks is not None:
                self.forks.close()
            (registry.runtime_dir() / f"{self.community}.json").unlink(missing_ok=True)
            if not self.mission.network.connect:  # ours: the next launch of the name makes new ones
                registry.credentials_path(self.community).unlink(missing_ok=True)
            if not self.children:  # nothing ran: leave no half-empty log folder behind
                shutil.rmtree(self.run_dir, ignore_errors=True)
        self.clear_status()
        now = time.monotonic()
        self.summary.wall_time = now - start_wall
        if self.ended_at is not None:
            self.summary.shutdown_time = now - self.ended_at
        return self.summary

    def _on_signal(self, signum, frame) -> None:
        first = self.stop_requested is None
        self.stop_requested = signum
        if first and not self.stopping:
            raise KeyboardInterrupt

    def start_router(self) -> list[str]:
        """The endpoints of the mission's router: `network.connect` (with the credentials named
        by `network.credentials`, if any), or a router of our own on loopback port 0, which
        writes the endpoint it listens on to a ready file once listening and admits only the
        holders of the mission's fresh credentials. Every process started from here reads them."""
        network = self.mission.network
        if network.connect:
            if network.credentials:
                self.credentials = str(Path(network.credentials).resolve())
        else:
            path = registry.credentials_path(self.community)
            self.credentials = str(path)
            self.router, endpoints = spawn_router(
                self.run_dir, self.mission.startup_timeout, path, lambda: self.stop_requested is not None
            )
        if self.credentials:
            os.environ[mission_credentials.VARIABLE] = self.credentials
        return list(network.connect) if network.connect else endpoints

    def app_count(self) -> int:
        """The apps `start_apps` starts: logger, surrogate server, a sim, pid and helm per vehicle, clock."""
        mission = self.mission
        services = mission.apps.logger.enabled + mission.needs_surrogate
        return services + len(ORDER) * (len(mission.vehicle_names) if mission.fleet else 1) + 1

    def claim_on_bus(self, bus: Bus, connect: list[str]) -> None:
        """Refuse a name another launcher uses on this bus (missions sharing a router, maybe from
        other hosts; the registry's lock covers this host). A claim token is declared first and
        then the claims and launcher tokens alive are listed, so of two launchers racing through
        one router at least the later one sees the other (both refuse when they cross exactly)."""
        root = f"{keys.community_root(self.community)}/launcher/claim"
        mine = f"{root}/{uuid.uuid4().hex}"
        bus.token(mine)
        timeout = min(2.0, self.mission.startup_timeout)
        others = [k for k in bus.alive(f"{root}/*", timeout=timeout) if k != mine]
        others += bus.alive(keys.alive(self.community, "launcher", "*"), timeout=timeout)
        if others:
            raise registry.NameTaken(
                f"a mission named {self.community!r} is already running or starting on {', '.join(connect)}; "
                "use --set name=OTHER"
            )

    def start_apps(self, bus: Bus, log_path: Path) -> None:
        """Start every process at once, so their imports overlap; the lock-stepped apps wait for
        the logger (`--after`) before they publish, and the clock for them and the surrogate
        server before it grants step 0, so the order of the mission is kept. The apps build their
        cores (the sim's LF tables) while the server loads its model: nobody asks it before step 0."""
        services, wanted = [], []
        mission = self.mission
        if self.mission.apps.logger.enabled:
            extra = ["--output", str(log_path)]
            if self.mission_path:
                extra += ["--mission-file", self.mission_path]
            self.spawn("logger", "logger", "logger", extra)
            services.append("logger")
            self.summary.log = str(log_path)
        if self.mission.needs_surrogate:
            self.spawn("surrogate", "surrogate", "surrogate")
            services.append("surrogate")
        after = [argument for role in services if role != "surrogate" for argument in ("--after", role)]
        for vehicle in mission.vehicle_names if mission.fleet else [None]:
            serves = ["--vehicle", vehicle] if vehicle else []
            for role in reversed(ORDER):
                app = keys.app_name(vehicle, role)
                instance = self.next_instance(app)
                self.spawn(role, instance, app, [*after, *serves])
                wanted.append((app, instance))
        self.spawn("clock", "clock", "clock", ["--after", "surrogate"] if "surrogate" in services else [])
        self.wait_alive(
            bus, [(role, role) for role in services] + wanted + [("clock", "clock")], self.mission.startup_timeout
        )
        self.clock_started = time.monotonic()  # the clock grants step 0 as soon as its token is up

    def supervise(self) -> None:
        while True:
            if self.status_line and time.monotonic() >= self.next_status:
                self.show_status()
            mail = self.mailbox.get(timeout=0.05)
            if mail is not None and self.handle(mail):
                self.blame_on_end()
                return
            if self.check_processes():
                self.blame_on_end()
                return

    def show_status(self) -> None:
        """One terminal line, rewritten each STATUS_INTERVAL: the clock's step, simulated time and
        achieved warp (against the requested one), the vehicle's speed and position."""
        self.next_status = time.monotonic() + STATUS_INTERVAL
        reply = self.caller.call("clock", "status", timeout=0.5)
        if reply is None or not reply.ok:
            return
        status = reply.data
        achieved = status.get("achieved_warp")
        warp = f"warp {'-' if achieved is None else f'{achieved:.1f}'}"
        if status["warp"] > 0:
            warp += f" of {status['warp']:g}"
        line = f"t {status['t']:8.2f} s  step {status['step']:>6}  {warp}"
        while (latest := self.latest_state.try_recv()) is not None:
            try:
                state = decode(latest[1], model_for_key(latest[0]), latest[0])
            except MessageError:
                continue
            self.positions[latest[0].split("/")[2]] = (state.u, state.x, state.y)
        if not self.mission.fleet and self.positions:
            u, x, y = next(iter(self.positions.values()))
            line += f"  u {u:5.2f} m/s  at ({x:8.2f}, {y:8.2f})"
        for vehicle, (u, x, y) in sorted(self.positions.items()) if self.mission.fleet else ():
            line += f"  {vehicle} {u:.1f} m/s ({x:.0f}, {y:.0f})"
        sys.stdout.write(f"\r\033[K{line}")
        sys.stdout.flush()
        self.showing_status = True

    def clear_status(self) -> None:
        if self.showing_status:
            sys.stdout.write("\r\033[K")
            sys.stdout.flush()
            self.showing_status = False

    def blame_on_end(self) -> None:
        """A mission that ended badly because a process died (the sim ends it at once when the
        surrogate server stops answering) names that process, as `check_processes` would have."""
        if self.summary.outcome in NORMAL_OUTCOMES or self.summary.failed_app:
            return
        if self.router_lost():
            culprit, code = "router", self.router.returncode
        else:
            dead = [
                c
                for c in self.children.values()
                if not c.retiring
                and (code := c.process.poll()) is not None
                and (code < 0 or (code != 0 and c.role in ("logger", "surrogate")))
            ]
            if not dead:
                return
            culprit, code = dead[0].instance, dead[0].process.returncode
        line = f"app {culprit} exited with code {code} at step {self.summary.steps}"
        print(f"nearsub launch: {line}", file=sys.stderr, flush=True)
        self.summary.failed_app = culprit
        self.summary.reason = f"{line}; {self.summary.reason}" if self.summary.reason else line

    def router_lost(self) -> bool:
        return self.router is not None and self.router.poll() is not None

    def check_processes(self) -> bool:
        """Raise LaunchError naming a process that left before the mission end (the router
        first: the apps leave because it did); True if the mission ended meanwhile."""
        if self.router_lost():
            code = self.router.returncode
            raise LaunchError(f"app router exited with code {code}: the launcher lost its apps", "router")
        for child in list(self.children.values()):
            code = child.process.poll()
            if code is None or child.retiring or (child.role == "clock" and self.ended(child.instance)):
                continue
            # Apps leave when the mission ends; the end may still be on its way to us.
            if self.mission_end_within(EXIT_GRACE if code == 0 else 0.2):
                return True
            if self.router_lost():
                return self.check_processes()
            step = "unknown (the clock is gone)" if child.role == "clock" else self.current_step()
            text = f"app {child.instance} exited with code {code} at step {step}\n{child.tail()}"
            raise LaunchError(text, child.instance)
        return False

    def mission_end_within(self, seconds: float) -> bool:
        """Handle mail for up to `seconds`; True as soon as the mission end is among it."""
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            mail = self.mailbox.get(timeout=min(left, 0.05))
            if mail is not None and self.handle(mail):
                return True
        return False

    def handle(self, mail) -> bool:
        """One mailbox item; True when the mission is over."""
        if mail.kind == "query":
            self.on_control(mail)
            return False
        if mail.kind in ("alive", "gone"):
            vehicle, _ = keys.split_app(keys.alive_role(mail.key))
            instance = keys.app_name(vehicle, mail.key.rsplit("/", 1)[-1])
            if instance != "launcher":
                kind = "app_joined" if mail.kind == "alive" else "app_left"
                self.publish_event(kind, f"{instance} {'joined' if kind == 'app_joined' else 'left'}")
            return False
        model = model_for_key(mail.key)
        if model is None:
            return False
        try:
            message = decode(mail.payload, model, mail.key)
        except MessageError:
            return False  # the receiving app reports it; the launcher only watches
        if isinstance(message, MissionEnd):
            self.ended_at = time.monotonic()
            self.summary.run_wall_time = self.ended_at - self.clock_started
            self.summary.cpu = self.cpu_now()
            self.summary.outcome = message.outcome
            self.summary.reason = message.reason
            self.summary.steps = message.step
            self.summary.sim_time = message.t
            return True
        if isinstance(message, Event):
            self.summary.events[message.kind] += 1
            if message.kind == "waypoint":
                self.summary.waypoints_reached += 1
            # events/<vehicle>/<instance> in a fleet: count and print them per vehicle
            vehicle = mail.key.split("/")[3] if self.mission.fleet and mail.key.count("/") > 3 else None
            if vehicle is not None:
                self.summary.record_vehicle_event(vehicle, message.kind)
            if not self.quiet and message.kind in ("waypoint", "collision", "swap", "error"):
                self.clear_status()
                who = f"{vehicle}: " if vehicle else ""
                print(f"  t={message.t:8.2f}  {message.kind:<10} {who}{message.detail}", file=sys.stderr, flush=True)
        return False

    def cpu_now(self) -> dict[str, float]:
        """CPU seconds of each process so far, by instance (the router as "router")."""
        processes = {c.instance: c.process for c in self.children.values()}
        if self.router is not None:
            processes["router"] = self.router
        cpu = {name: process_cpu(p) for name, p in processes.items()}
        return {name: seconds for name, seconds in cpu.items() if seconds is not None}

    def drain_mailbox(self) -> None:
        while (mail := self.mailbox.get(timeout=0.0)) is not None:
            if mail.kind == "sample":
                self.handle(mail)

    def current_step(self) -> str:
        reply = self.caller.call("clock", "status", timeout=1.0)
        if reply is not None and reply.ok:
            return str(reply.data["step"])
        return "unknown (the clock did not answer)"

    def publish_event(self, kind: str, detail: str, step: int = 0, data: dict | None = None) -> None:
        event = Event(step=step, t=step * self.mission.dt, source="launcher", kind=kind, detail=detail, data=data or {})
        self.event_pub.put(encode(event))

    def abort(self, outcome: str, reason: str) -> None:
        """End the mission from outside the clock, so every app and the logger wind down."""
        self.summary.outcome, self.summary.reason = outcome, reason
        try:
            step = 0 if self.router_lost() else int(self.current_step())
        except ValueError:
            step = 0
        self.summary.steps, self.summary.sim_time = step, step * self.mission.dt
        self.end_pub.put(
            encode(MissionEnd(step=step, t=step * self.mission.dt, source="launcher", outcome=outcome, reason=reason))
        )

    def fail(self, exc: LaunchError) -> None:
        text = str(exc)
        print(f"nearsub launch: {text}", file=sys.stderr, flush=True)
        self.summary.failed_app = exc.app
        self.abort("error", text.splitlines()[0])

    # -- swap ---------------------------------------------------------------------------------
    def on_control(self, mail) -> None:
        try:
            request = msgpack.unpackb(mail.payload)
            command = request["cmd"]
        except Exception:
            mail.reply_error("launcher: control request is not a msgpack map with 'cmd'")
            return
        if command != "swap":
            mail.reply_error(f"launcher: unknown command {command!r}")
            return
        try:
            at = request.get("at_step")
            vehicle = request.get("vehicle")
            result = self.swap(
                str(request.get("app", "")),
                list(request.get("set", [])),
                None if at is None else int(at),
                None if vehicle is None else str(vehicle),
            )
        except SwapRefused as exc:
            mail.reply(msgpack.packb({"ok": False, "refused": str(exc)}))
            return
        except LaunchError as exc:
            mail.reply_error(str(exc))
            return
        mail.reply(msgpack.packb(result))

    def swap(self, role: str, overrides: list[str], at_step: int | None = None, vehicle: str | None = None) -> dict:
        """Replace `role` (of `vehicle`, which a mission of several vehicles needs) at a step boundary."""
        if role not in ORDER:
            raise SwapRefused(f"cannot swap {role!r}: only {', '.join(ORDER)} can be swapped")
        vehicle = self.swapped_vehicle(vehicle)
        app = keys.app_name(vehicle, role)
        old = next(
            (c for c in self.children.values() if c.role == app and not c.retiring and c.process.poll() is None), None
        )
        if old is None:
            raise SwapRefused(f"no running {app} to swap")
        prefixed = [o if o.startswith("apps.") else f"apps.{role}.{o}" for o in overrides]
        if vehicle is not None:  # that vehicle's own settings
            prefixed = [f"vehicles.{vehicle}.{o}" for o in prefixed]
        try:
            mission_from_dict(apply_overrides(self.mission.model_dump(mode="json"), prefixed), "--with")
        except MissionError as exc:
            raise SwapRefused(str(exc)) from None
        wait = self.mission.step_timeout + 5
        if at_step is not None:
            wait += 600.0  # the clock answers when it reaches the step
        paused = self.caller.call("clock", "pause", timeout=wait, **({} if at_step is None else {"at": at_step}))
        if paused is None:
            raise LaunchError("the clock did not pause")
        if not paused.ok:
            raise LaunchError(paused.error)
        step = int(paused.data["step"])
        instance = self.next_instance(app)
        extra = ["--takeover", old.instance, "--resume-step", str(step)]
        for override in prefixed:
            extra += ["--set", override]
        if vehicle is not None:
            extra += ["--vehicle", vehicle]
        new = self.spawn(role, instance, app, extra)
        try:
            self.wait_alive(self.bus, [(app, instance)], self.mission.startup_timeout)
        except LaunchError:
            stop([new.process], grace=0.0)
            new.retiring = True
            self.caller.call("clock", "resume", timeout=5.0)
            raise
        old.retiring = True
        self.caller.call(old.instance, "retire", timeout=5.0)
        stop([old.process], grace=5.0)
        detail = f"{old.instance} -> {instance} at step {step}" + (f" with {', '.join(prefixed)}" if prefixed else "")
        self.publish_event("swap", detail, step, {"old": old.instance, "new": instance, "step": step, "set": prefixed})
        self.summary.swaps.append({"old": old.instance, "new": instance, "step": step})
        self.caller.call("clock", "resume", timeout=5.0)
        return {"ok": True, "old": old.instance, "new": instance, "step": step}

    def swapped_vehicle(self, vehicle: str | None) -> str | None:
        """The vehicle a swap serves: the one named, the only one, or None without [[vehicles]]."""
        names = self.mission.vehicle_names
        if not self.mission.fleet:
            if vehicle is not None:
                raise SwapRefused(f"vehicle {vehicle!r}: mission {self.community!r} has no [[vehicles]]")
            return None
        if vehicle is None and len(names) > 1:
            raise SwapRefused(f"mission {self.community!r} has several vehicles ({', '.join(names)}): name one")
        if vehicle is not None and vehicle not in names:
            raise SwapRefused(f"no vehicle named {vehicle!r} (the mission's vehicles: {', '.join(names)})")
        return vehicle or names[0]


def exit_code(summary: Summary) -> int:
    if summary.outcome in NORMAL_OUTCOMES:
        return 0
    return 130 if summary.outcome == "interrupted" else 1
