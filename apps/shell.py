"""The process shell of every lock-stepped app (helm, pid, sim): one lifecycle for all.

Start-up: open the session, subscribe one ordered stream to exactly what this app consumes (its
input topics, the clock's traffic, its own control and reply keys; runtime/bus.py), declare
publishers, optionally take over from a running instance, publish "running", declare the
liveliness token. Then the loop drains the stream in arrival order:
- a tick grants the steps up to the one it carries (runtime/clock.py);
- an input is validated and offered to the stepper (malformed or out-of-protocol messages are
  reported as rate-limited error events and dropped; the app keeps running); an operator's
  desired state or input (source "operator", `nearsub tap pub`) overrides the producer's from
  the next step this app runs, recorded in an info event with that step;
- an end request (an Ack with `end`) from any app at step k: this app runs no step after k;
- the stepper (runtime/lifecycle.py) then runs every step it may, and the shell publishes what
  it returns, in order;
- control requests (handover, retire) are answered between steps;
- the mission end leaves the loop.

A swapped-in app (`--takeover OLD`) asks the old instance for a handover: the core's progress and
the inputs it holds for the step where the clock paused. It continues from there, so no step is
skipped or repeated.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import uuid
from collections.abc import Callable

from nearsub.apps.entry import AppError, load_run, run_app
from nearsub.common.mission.schema import RunConfig
from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Bus, DeadlineExceeded, app_endpoints, deadline, signal_self
from nearsub.common.runtime.lifecycle import (
    ACK,
    EVENTS,
    OPERATOR,
    OPERATOR_ONLY,
    OPERATOR_TOPICS,
    PRODUCER,
    Core,
    Schedule,
    Stepper,
    control_reply,
)
from nearsub.common.runtime.messages import (
    VEHICLE_TOPICS,
    Ack,
    AppStatus,
    Control,
    ControlReply,
    Event,
    Message,
    MessageError,
    Tick,
    decode,
    encode,
)
from nearsub.common.surrogate.query import ServiceError

HANDOVER_TIMEOUT = 30.0
ERROR_INTERVAL = 1.0  # wall seconds between error events; the rejections in between are counted


def app_arguments(description: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--run", required=True, help="run configuration written by `nearsub launch`")
    parser.add_argument("--instance", required=True, help="unique instance name, e.g. helm-1 or auv1/helm-1")
    parser.add_argument("--vehicle", help="the [[vehicles]] entry this app serves (a mission with a fleet)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="mission override")
    parser.add_argument("--takeover", metavar="INSTANCE", help="take over from a running instance (swap)")
    parser.add_argument("--resume-step", type=int, help="the step at which the clock paused (swap)")
    parser.add_argument(
        "--after", action="append", default=[], metavar="ROLE", help="wait for this role's liveliness token first"
    )
    return parser


def wait_for_roles(bus: Bus, community: str, roles: list[str], timeout: float) -> list[str]:
    """Wait up to `timeout` wall seconds for a liveliness token of each role; the roles missing."""
    end = time.monotonic() + timeout
    while True:
        alive = {keys.alive_role(key) for key in bus.alive(keys.all_alive(community), timeout=0.5)}
        missing = [role for role in roles if role not in alive]
        if not missing or time.monotonic() > end:
            return missing
        time.sleep(0.02)


class AppShell:
    """Runs one core under the lock-step protocol. `core_factory(mission, surrogate)` builds the
    core once the bus is open; `surrogate` is the remote surrogate server when the mission needs it.
    In a fleet, `vehicle` names the entry the app serves: the core gets that vehicle's mission
    (`Mission.member`) and the app hears its own vehicle's inputs only, and of the clock only the
    ticks and the end (the clock alone decides a fleet's end and never grants past it)."""

    def __init__(self, core_factory: Callable[..., Core], run: RunConfig, instance: str, vehicle: str | None = None):
        self.core_factory = core_factory
        self.run = run
        self.instance = instance
        self.lockstep = run.mission.lockstep()
        mission = self.mission = run.mission.member(vehicle)
        c = self.community = mission.name
        self.vehicle = mission.vehicle_name
        self.named = vehicle  # None: the app names of a mission without [[vehicles]]
        self.dt = mission.dt
        self.tick_key = keys.tick(c)
        self.end_key = keys.mission_end(c)
        self.control_key = keys.control(c, instance)
        self.reply_key = keys.reply(c, instance)
        self.ack_prefix = keys.ack(c, "")
        self.handover_request: Control | None = None
        self.backlog: list[tuple[str, bytes]] = []
        self.last_error_report = -math.inf
        self.unreported_errors = 0

    # -- start-up -----------------------------------------------------------------------------
    def serve(self, takeover: str | None = None, resume_step: int | None = None, after: list[str] = ()) -> int:
        """`after`: roles started beside this app whose tokens it waits for before it builds its
        core (the surrogate server) and publishes anything (the logger, so the log misses nothing)."""
        with Bus(app_endpoints(self.run.connect)) as bus:
            self.bus = bus
            c = self.community
            mission = self.mission
            if missing := wait_for_roles(bus, c, list(after), mission.startup_timeout):
                raise AppError(f"{', '.join(missing)} did not start within {mission.startup_timeout:g} s")
            surrogate = None
            if mission.needs_surrogate:
                from nearsub.apps.services import RemoteSurrogate  # the pid never asks: no import

                surrogate = RemoteSurrogate(bus, c)
            self.core = self.core_factory(mission, surrogate)
            # A surrogate server that stops answering ends the mission, naming it.
            shared = self.lockstep.shared
            schedule = Schedule(mission.periods())
            self.stepper = Stepper(
                self.core,
                schedule,
                self.dt,
                mission.max_steps,
                recoverable=(ServiceError,),
                ends_itself=not shared,
                window=self.lockstep.window,
            )
            pokes = [leaf for leaf, role in OPERATOR_ONLY.items() if role == self.core.role]
            self.input_of_key = {self.input_key(leaf, schedule): leaf for leaf in (*self.core.inputs, *pokes)}
            clock = [self.tick_key, self.end_key] if shared else [keys.clock_traffic(c)]
            self.stream = bus.inputs([*self.input_of_key, *clock, self.control_key, self.reply_key])
            bus.on_liveliness_lost(keys.alive(c, "launcher", "*"), signal_self())
            self.publishers = {
                leaf: bus.publisher(keys.vehicle_topic(c, self.vehicle, leaf)) for leaf in self.core.outputs
            }
            self.feed_publishers = {
                leaf: [
                    (stride, bus.publisher(keys.feed(c, self.vehicle, leaf, stride))) for stride in schedule.feeds(leaf)
                ]
                for leaf in self.core.outputs
                if leaf in PRODUCER
            }
            self.app = keys.app_name(self.named, self.core.role)
            self.publishers[ACK] = bus.publisher(keys.ack(c, self.app))
            self.publishers[EVENTS] = bus.publisher(keys.events(c, self.instance))
            self.status_pub = bus.publisher(keys.status(c, self.instance))
            if takeover is not None:
                self.take_over(takeover, resume_step)
            self.publish_status("running")
            bus.token(keys.alive(c, self.app, self.instance))
            try:
                return self.loop()
            finally:
                if self.unreported_errors:
                    self.report_error("mission over", force=True)
                self.publish_status("stopping")

    def take_over(self, old_instance: str, resume_step: int) -> None:
        request = Control(
            step=resume_step,
            t=resume_step * self.dt,
            source=self.instance,
            cmd="handover",
            args={"step": resume_step},
            request_id=uuid.uuid4().hex,
            reply_to=self.instance,
        )
        self.bus.join()
        self.bus.put_when_matched(keys.control(self.community, old_instance), encode(request))
        try:
            with deadline(HANDOVER_TIMEOUT):
                while True:
                    key, payload = self.stream.recv()
                    if key != self.reply_key:
                        self.backlog.append((key, payload))
                        continue
                    reply = decode(payload, ControlReply, key)
                    if reply.request_id == request.request_id:
                        break
        except DeadlineExceeded:
            raise AppError(f"no handover from {old_instance} within {HANDOVER_TIMEOUT:g} s") from None
        if not reply.ok:
            raise AppError(f"handover from {old_instance} failed: {reply.error}")
        self.stepper.take_over(bytes.fromhex(reply.data["handover"]), resume_step)

    # -- the loop -----------------------------------------------------------------------------
    def loop(self) -> int:
        stepper = self.stepper
        while True:
            key, payload = self.backlog.pop(0) if self.backlog else self.stream.recv()
            if key in self.input_of_key:
                self.on_input(self.input_of_key[key], payload)
            elif key == self.tick_key:
                tick = self.decode_or_report(payload, Tick, key)
                if tick is not None and (error := stepper.grant(tick.step)):
                    self.report_error(error)
            elif key.startswith(self.ack_prefix):
                ack = self.decode_or_report(payload, Ack, key)
                if ack is not None and ack.end is not None:
                    stepper.end_after(ack.step)
            elif key == self.control_key:
                request = self.decode_or_report(payload, Control, key)
                if request is not None and self.on_control(request):
                    return 0
            elif key == self.end_key:
                return 0
            else:
                continue
            for channel, message in stepper.produce():  # published as they come (`Iteration.then`)
                if channel == EVENTS and message.kind == "error":
                    print(f"[{self.instance}] error: {message.detail}", file=sys.stderr, flush=True)
                payload = encode(message)
                self.publishers[channel].put(payload)
                for stride, feed in self.feed_publishers.get(channel, ()):
                    if message.step % stride == 0:
                        feed.put(payload)
            self.try_handover()

    def input_key(self, leaf: str, schedule: Schedule) -> str:
        """The key input `leaf` arrives on: its feed when this app reads it strided (`Schedule.stride`)."""
        if leaf in PRODUCER and (stride := schedule.stride(leaf, self.core.role)) in schedule.feeds(leaf):
            return keys.feed(self.community, self.vehicle, leaf, stride)
        return keys.vehicle_topic(self.community, self.vehicle, leaf)

    def on_input(self, leaf: str, payload: bytes) -> None:
        key = keys.vehicle_topic(self.community, self.vehicle, leaf)
        message = self.decode_or_report(payload, VEHICLE_TOPICS[leaf], key)
        if message is not None and message.source == OPERATOR and leaf in OPERATOR_TOPICS:
            event = self.stepper.override(leaf, message)
            print(f"[{self.instance}] {event.detail}", file=sys.stderr, flush=True)
            self.publishers[EVENTS].put(encode(event))
        elif message is not None:
            error = self.stepper.offer(leaf, message)
            if error:
                self.report_error(error)

    # -- control: handover and retire (swap) -------------------------------------------------
    def on_control(self, request: Control) -> bool:
        """Handle a control request; True means leave the loop."""
        if request.cmd == "handover":
            self.handover_request = request
            return False
        if request.cmd == "retire":
            self.reply(request, data={"instance": self.instance})
            return True
        self.reply(request, ok=False, error=f"{self.instance}: unknown control command {request.cmd!r}")
        return False

    def try_handover(self) -> None:
        request = self.handover_request
        if request is None:
            return
        handover = self.stepper.handover(int(request.args["step"]))
        if handover is not None:
            self.reply(request, data={"handover": handover.hex()})
            self.handover_request = None

    def reply(self, request: Control, **answer) -> None:
        reply = control_reply(request, self.instance, self.stepper.step, self.dt, **answer)
        self.bus.put_reply(keys.reply(self.community, request.reply_to), encode(reply))

    # -- reporting ----------------------------------------------------------------------------
    def decode_or_report(self, payload: bytes, model: type[Message], key: str) -> Message | None:
        try:
            return decode(payload, model, key)
        except MessageError as exc:
            self.report_error(f"rejected message: {exc}")
            return None

    def report_error(self, text: str, force: bool = False) -> None:
        """An error event, at most one per ERROR_INTERVAL: a flood of bad messages must not flood
        the events (nor cost the shell its pace); the next event counts those left unreported."""
        now = time.monotonic()
        if now - self.last_error_report < ERROR_INTERVAL and not force:
            self.unreported_errors += 1
            return
        if self.unreported_errors:
            text = f"{text} (and {self.unreported_errors} more errors since the last report)"
        self.last_error_report, self.unreported_errors = now, 0
        print(f"[{self.instance}] error: {text}", file=sys.stderr, flush=True)
        step = self.stepper.step
        event = Event(step=step, t=step * self.dt, source=self.core.role, kind="error", detail=text)
        self.publishers[EVENTS].put(encode(event))

    def publish_status(self, state: str) -> None:
        step = self.stepper.step
        status = AppStatus(
            step=step, t=step * self.dt, source=self.core.role, app=self.app, instance=self.instance, state=state
        )
        self.status_pub.put(encode(status))


def main_for(core_factory, description: str, argv=None) -> int:
    """The `main` of the helm, pid and sim: `core_factory(mission, surrogate)` builds the core."""

    def body(args) -> int:
        run = load_run(args.run, args.set)
        try:
            run.mission.member(args.vehicle)
        except KeyError as exc:
            raise AppError(f"--vehicle: {exc.args[0]}", 2) from None
        shell = AppShell(core_factory, run, args.instance, args.vehicle)
        return shell.serve(args.takeover, args.resume_step, args.after)

    return run_app(app_arguments(description), body, argv)
