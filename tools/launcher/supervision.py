"""The run of a launch (`Launcher.run`): the router, the apps, then the supervision of every process
and of the bus until the mission ends, and the stop."""

from __future__ import annotations

import os
import shutil
import signal
import sys
import time
from collections import Counter
from datetime import datetime
from pathlib import Path

from nearsub.common.mission.schema import Mission, RunConfig
from nearsub.common.runtime import forkserver, keys
from nearsub.common.runtime.bus import Bus, BusError, Endpoints, Mailbox, app_environment
from nearsub.common.runtime.lifecycle import ORDER
from nearsub.common.runtime.logfile import no_space_left
from nearsub.common.runtime.messages import Event, MessageError, MissionEnd, decode, encode, model_for_key

from ..support.caller import Caller
from . import registration, swap
from .processes import LaunchError, Processes, fork_preload, spawn_router
from .status import NORMAL_OUTCOMES, Console, Summary, interrupted_reason

EXIT_GRACE = 2.0  # wall seconds to wait for the mission end after an app left with code 0


class Launcher:
    """One launch of `mission`: `run` starts its processes, supervises them until the mission ends
    and returns the Summary. `companions` are started with the run file and the apps' environment
    once the apps are up (`launch --view`, `--foxglove`).

    A fleet over several hosts (docs/network.md, "A fleet over several hosts"): `here` names the
    vehicles whose helm, pid and sim this launch starts (None: every vehicle); the others' are
    started by a launch with `join` on another host, on the same router. The launch without
    `join` is the mission's: the logger, the surrogate server, the clock (which waits for every
    vehicle's apps wherever they run), the name on the bus, the registry entry, swaps and the
    app_joined/app_left events. A joining launch starts its vehicles' apps only, supervises them
    and ends with the mission (an app of its own that fails ends the mission, as on one host)."""

    def __init__(
        self,
        mission: Mission,
        mission_path: str | None,
        log_root: str,
        quiet: bool = False,
        companions=(),
        here: list[str] | None = None,
        join: bool = False,
    ):
        self.mission = mission
        self.here = list(mission.vehicle_names) if here is None else list(here)
        self.join = join
        self.companions = list(companions)  # each returns its process, which is stopped first
        self.mission_path = mission_path
        self.community = mission.name
        self.console = Console(quiet)
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        self.run_dir = Path(log_root) / f"{self.community}-{stamp}-{os.getpid()}"
        self.processes = Processes(self.run_dir, mission.startup_timeout, self.console.say)
        self.summary = Summary(self.community, warp=mission.warp)
        for name in mission.vehicle_names if mission.fleet else ():
            self.summary.vehicles[name] = {"waypoints_reached": 0, "events": Counter()}
        self.ended_at: float | None = None
        self.stop_requested: int | None = None
        self.credentials: str | None = None  # the file the mission's router requires
        self.stopping = False
        self.clock_started = time.monotonic()

    def interrupted(self) -> bool:
        return self.stop_requested is not None

    # -- the run ------------------------------------------------------------------------------
    def run(self) -> Summary:
        """Start, supervise and stop the mission. Raises registry.NameTaken when a live launcher
        of the same name is on the bus (a mission on a shared router)."""
        self.run_dir.mkdir(parents=True, exist_ok=True)
        processes = self.processes
        start_wall = self.console.launched = time.monotonic()
        previous_handlers = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            processes.forks = forkserver.start(fork_preload(self.mission))  # loads while the router starts
            connect = self.start_router()
            if processes.router is not None:
                self.console.say(f"started router (pid {processes.router.pid}) on {', '.join(connect)}")
            # Every app started from here, swaps included: how long it keeps trying to reach the
            # router, the credentials, how it links (bus.app_link) and its Zenoh threads.
            processes.env = app_environment(connect, self.app_count(), self.mission.startup_timeout, self.credentials)
            RunConfig(mission=self.mission, connect=connect, log_dir=str(self.run_dir)).save(processes.run_file)
            log_path = self.run_dir / f"{self.community}.mcap"
            endpoints = Endpoints(
                "client", tuple(connect), timeout=self.mission.startup_timeout, credentials=self.credentials
            )
            with Bus(endpoints) as bus:
                self.bus = bus
                self.mailbox = Mailbox()
                c = self.community
                if not self.join:
                    registration.claim_on_bus(bus, c, connect, self.mission.startup_timeout)
                bus.subscribe(keys.all_events(c), self.mailbox)
                bus.subscribe(keys.mission_end(c), self.mailbox)
                self.caller = Caller(bus, c, "launcher")
                self.event_pub = bus.publisher(keys.events(c, "launcher"))
                self.end_pub = bus.publisher(keys.mission_end(c))
                if not self.join:  # the mission's launch alone: one answer to a swap, one event per app
                    bus.queryable(keys.launcher_control(c), self.mailbox)
                    bus.watch_liveliness(keys.all_alive(c), self.mailbox, history=False)
                    bus.token(keys.alive(c, "launcher", "launcher"))
                # For people only; lossy: a display must never slow the mission down.
                depth = 256 * len(self.mission.vehicle_names)
                self.helm_progress = (
                    None if self.console.quiet else bus.stream(keys.vehicle_topic(c, "*", "helm"), depth, True)
                )
                try:
                    self.start_apps(bus, log_path)
                    self.summary.startup_time = time.monotonic() - start_wall
                    self.console.say(
                        f"mission {c} running: {len(processes.children) + (processes.router is not None)} "
                        f"processes up in {self.summary.startup_time:.2f} s"
                    )
                    if not self.join:
                        registration.register(self.mission, connect, log_path, self.credentials)
                    processes.companions += [start(processes.run_file, processes.env) for start in self.companions]
                    if self.console.status_line:
                        vehicles = self.mission.vehicle_names
                        self.latest_state = bus.stream(keys.vehicle_topic(c, "*", "state"), len(vehicles), True)
                    self.supervise()
                    self.console.helm_phases(self.helm_progress, self.mission.fleet)  # the last step's
                except LaunchError as exc:
                    self.fail(exc)
                except KeyboardInterrupt:
                    self.abort("interrupted", interrupted_reason(self.summary))
                self.stopping = True
                processes.stop_all()
                self.drain_mailbox()
        except (BusError, LaunchError) as exc:  # before any app started: there is no mission to end
            self.summary.outcome, self.summary.reason = "error", self.with_disk(str(exc)).splitlines()[0]
            self.summary.failed_app = getattr(exc, "app", None)
            print(f"nearsub launch: {exc}", file=sys.stderr, flush=True)
        except KeyboardInterrupt:
            self.summary.outcome, self.summary.reason = "interrupted", interrupted_reason(self.summary)
        finally:
            self.stopping = True
            for signum, handler in previous_handlers.items():
                signal.signal(signum, handler)
            processes.close()
            if not self.join:
                registration.forget(self.mission)
            if not processes.children:  # nothing ran: leave no half-empty log folder behind
                shutil.rmtree(self.run_dir, ignore_errors=True)
        self.console.clear_status()
        now = time.monotonic()
        self.summary.wall_time = now - start_wall
        if self.ended_at is not None:
            self.summary.shutdown_time = now - self.ended_at
        self.summary.approaches = self.approaches()
        return self.summary

    def approaches(self):
        """The closest approaches the finished log shows (None without a log or states)."""
        log = Path(self.summary.log) if self.summary.log else None
        if log is None or not log.is_file() or not self.summary.startup_time:
            return None
        from nearsub.common.analysis.approach import log_approaches
        from nearsub.common.runtime.logfile import read_log

        states = [keys.vehicle_topic(self.community, name, "state") for name in self.mission.vehicle_names]
        return log_approaches(read_log(log, states))

    def _on_signal(self, signum, frame) -> None:
        first = self.stop_requested is None
        self.stop_requested = signum
        if first and not self.stopping:
            raise KeyboardInterrupt

    def start_router(self) -> list[str]:
        """The endpoints of the mission's router: `network.connect` (with the credentials named
        by `network.credentials`, if any), or a router of our own on loopback port 0, which
        writes the endpoint it listens on to a ready file once listening and admits only the
        holders of the mission's fresh credentials. Every process started from here gets them."""
        network = self.mission.network
        self.credentials = registration.credentials_file(self.mission)
        if network.connect:
            return list(network.connect)
        self.processes.router, endpoints = spawn_router(
            self.run_dir, self.mission.startup_timeout, Path(self.credentials), self.interrupted
        )
        return endpoints

    def app_count(self) -> int:
        """The apps `start_apps` starts: logger, surrogate server, a sim, pid and helm per vehicle
        here, clock (a joining launch: its vehicles' apps alone)."""
        mission = self.mission
        services = 0 if self.join else mission.apps.logger.enabled + mission.needs_surrogate + 1
        return services + len(ORDER) * (len(self.here) if mission.fleet else 1)

    def start_apps(self, bus: Bus, log_path: Path) -> None:
        """Start every process at once, so their imports overlap; the lock-stepped apps wait for
        the logger (`--after`) before they publish, and the clock for them and the surrogate
        server before it grants step 0, so the order of the mission is kept. The apps build their
        cores (the sim's LF tables) while the server loads its model: nobody asks it before step 0."""
        services, wanted = [], []
        mission, processes = self.mission, self.processes
        if mission.apps.logger.enabled and not self.join:
            extra = ["--output", str(log_path)]
            if self.mission_path:
                extra += ["--mission-file", self.mission_path]
            processes.spawn("logger", "logger", "logger", extra)
            services.append("logger")
            self.summary.log = str(log_path)
        if mission.needs_surrogate and not self.join:
            processes.spawn("surrogate", "surrogate", "surrogate")
            services.append("surrogate")
        # A joining launch's apps wait for the mission's logger, wherever it runs.
        logged = mission.apps.logger.enabled and (self.join or "logger" in services)
        after = ["--after", "logger"] if logged else []
        for vehicle in self.here if mission.fleet else [None]:
            serves = ["--vehicle", vehicle] if vehicle else []
            for role in reversed(ORDER):
                app = keys.app_name(vehicle, role)
                instance = processes.next_instance(app)
                processes.spawn(role, instance, app, [*after, *serves])
                wanted.append((app, instance))
        everyone = [(role, role) for role in services] + wanted
        if not self.join:
            processes.spawn("clock", "clock", "clock", ["--after", "surrogate"] if "surrogate" in services else [])
            everyone.append(("clock", "clock"))
        processes.wait_alive(bus, self.community, everyone, mission.startup_timeout, self.interrupted)
        self.clock_started = time.monotonic()  # the clock grants step 0 as soon as its token is up

    # -- supervision --------------------------------------------------------------------------
    def supervise(self) -> None:
        while True:
            if self.interrupted():  # the handler's KeyboardInterrupt is lost if it lands in a finalizer (__del__)
                raise KeyboardInterrupt
            self.console.helm_phases(self.helm_progress, self.mission.fleet)
            if self.console.status_due():
                self.console.show_status(self.caller, self.latest_state, self.mission.fleet)
            mail = self.mailbox.get(timeout=0.05)
            if mail is not None and self.handle(mail):
                self.blame_on_end()
                return
            if self.check_processes():
                self.blame_on_end()
                return

    def blame_on_end(self) -> None:
        """A mission that ended badly because a process died (the sim ends it at once when the
        surrogate server stops answering) names that process, as `check_processes` would have."""
        if self.summary.outcome in NORMAL_OUTCOMES or self.summary.failed_app:
            return
        processes = self.processes
        at_step = f"at step {self.summary.steps}"
        if processes.router_lost():
            culprit, line = "router", f"app router exited with code {processes.router.returncode} {at_step}"
        else:
            dead = processes.killed()
            if not dead:
                return
            culprit, line = dead[0].instance, dead[0].exited(at_step)
        line = self.with_disk(line)
        print(f"nearsub launch: {line}", file=sys.stderr, flush=True)
        self.summary.failed_app = culprit
        self.summary.reason = f"{line}; {self.summary.reason}" if self.summary.reason else line

    def with_disk(self, text: str) -> str:
        """`text`, its first line saying so when the log folder's disk is full: the likely cause
        of a process's exit, which its own output file (on that disk) cannot tell."""
        if not no_space_left(self.run_dir):
            return text
        first, _, rest = text.partition("\n")
        return f"{first}: no space left on {self.run_dir}" + (f"\n{rest}" if rest else "")

    def check_processes(self) -> bool:
        """Raise LaunchError naming a process that left before the mission end (the router
        first: the apps leave because it did); True if the mission ended meanwhile."""
        processes = self.processes
        if processes.router_lost():
            code = processes.router.returncode
            raise LaunchError(f"app router exited with code {code}: the launcher lost its apps", "router")
        for child in list(processes.children.values()):
            code = child.process.poll()
            if code is None or child.retiring or (child.role == "clock" and processes.ended(child.instance)):
                continue
            # Apps leave when the mission ends; the end may still be on its way to us.
            if self.mission_end_within(EXIT_GRACE if code == 0 else 0.2):
                return True
            if processes.router_lost():
                return self.check_processes()
            step = "unknown (the clock is gone)" if child.role == "clock" else self.current_step()
            text = f"{child.exited(f'at step {step}')}\n{child.tail()}"
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
            swap.answer(self, mail)
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
            self.summary.cpu = self.processes.cpu_now()
            self.summary.record_end(message)
            return True
        if isinstance(message, Event):
            self.summary.events[message.kind] += 1
            if message.kind == "waypoint":
                self.summary.waypoints_reached += 1
            # events/<vehicle>/<instance> in a fleet: count and print them per vehicle
            vehicle = mail.key.split("/")[3] if self.mission.fleet and mail.key.count("/") > 3 else None
            if vehicle is not None:
                self.summary.record_vehicle_event(vehicle, message.kind)
            self.console.event(message, vehicle)
        return False

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
        try:  # the clock grants nothing before every app is up: no need to ask it then
            step = 0 if self.processes.router_lost() or not self.summary.startup_time else int(self.current_step())
        except ValueError:
            step = 0
        self.summary.steps, self.summary.sim_time = step, step * self.mission.dt
        self.end_pub.put(
            encode(MissionEnd(step=step, t=step * self.mission.dt, source="launcher", outcome=outcome, reason=reason))
        )

    def fail(self, exc: LaunchError) -> None:
        text = self.with_disk(str(exc))
        print(f"nearsub launch: {text}", file=sys.stderr, flush=True)
        self.summary.failed_app = exc.app
        self.abort("error", text.splitlines()[0])
