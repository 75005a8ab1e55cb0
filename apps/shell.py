"""The process shell of every lock-stepped app (helm, pid, sim): one lifecycle for all.

It subscribes to the clock's ticks, the app's input topics and its control queryable, all into one
mailbox; declares a liveliness token; then loops: on a tick it waits until the inputs the schedule
expects have arrived, hands them to the core (new mail), runs the core (iterate), publishes the
outputs and events, and acknowledges the step. Malformed messages are reported as error events
and dropped; the app keeps running.

A swapped-in app (`--takeover OLD`) first asks the old instance for a handover: the core's
progress and the inputs it holds for the step where the clock paused. It then continues from
there, so no step is skipped or repeated.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys

import msgpack

from nearsub.common import keys
from nearsub.common.bus import Bus, Endpoints, Mailbox
from nearsub.common.lifecycle import Core, Inbox, Schedule
from nearsub.common.messages import (
    VEHICLE_TOPICS,
    Ack,
    AppStatus,
    Event,
    Message,
    MessageError,
    Tick,
    decode,
    encode,
)
from nearsub.common.mission import MissionError, RunConfig, apply_overrides, mission_from_dict

EXIT_LAUNCHER_GONE = 3


def terminate_on_sigterm() -> None:
    """Turn SIGTERM into SystemExit so `with` blocks close the Zenoh session and files."""

    def handler(signum, frame):
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, handler)


def app_arguments(description: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--run", required=True, help="run configuration written by `nearsub launch`")
    parser.add_argument("--instance", required=True, help="unique instance name, e.g. helm-1")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="mission override")
    parser.add_argument("--takeover", metavar="INSTANCE", help="take over from a running instance (swap)")
    parser.add_argument("--resume-step", type=int, help="the step at which the clock paused (swap)")
    return parser


def load_run(args) -> RunConfig:
    run = RunConfig.load(args.run)
    if args.set:
        data = apply_overrides(run.mission.model_dump(mode="json"), args.set)
        run = run.model_copy(update={"mission": mission_from_dict(data, "--set")})
    return run


class AppShell:
    """Runs one core under the lock-step protocol."""

    def __init__(self, core: Core, run: RunConfig, instance: str):
        self.core = core
        self.run = run
        self.instance = instance
        mission = run.mission
        self.community = mission.name
        self.vehicle = mission.vehicle_name
        self.dt = mission.dt
        self.schedule = Schedule(mission.periods())
        self.inbox = Inbox(core.inputs, self.schedule)
        self.topic_of_key = {keys.vehicle_topic(self.community, self.vehicle, leaf): leaf for leaf in core.inputs}
        self.pending: int | None = None
        self.started = False
        self.step = 0
        self.deferred_handover = None
        self.parent = os.getppid()

    # -- wiring -------------------------------------------------------------------------------
    def serve(self, takeover: str | None = None, resume_step: int | None = None) -> int:
        endpoints = Endpoints("client", tuple(self.run.connect))
        with Bus(endpoints) as bus:
            self.bus = bus
            self.mailbox = Mailbox()
            c = self.community
            bus.subscribe(keys.tick(c), self.mailbox)
            bus.subscribe(keys.mission_end(c), self.mailbox)
            for key in self.topic_of_key:
                bus.subscribe(key, self.mailbox)
            bus.queryable(keys.app_control(c, self.instance), self.mailbox)
            bus.watch_liveliness(keys.alive(c, "launcher", "*"), self.mailbox)
            self.outputs = {
                leaf: bus.publisher(keys.vehicle_topic(c, self.vehicle, leaf)) for leaf in self.core.outputs
            }
            self.ack_pub = bus.publisher(keys.ack(c, self.core.role))
            self.event_pub = bus.publisher(keys.events(c, self.instance))
            self.status_pub = bus.publisher(keys.status(c, self.instance))
            if takeover is not None:
                self.take_over(takeover, resume_step)
            self.publish_status("running")
            bus.token(keys.alive(c, self.core.role, self.instance))
            try:
                return self.loop()
            finally:
                self.publish_status("stopping")

    def take_over(self, old_instance: str, resume_step: int) -> None:
        request = msgpack.packb({"cmd": "handover", "step": resume_step})
        replies = self.bus.request(keys.app_control(self.community, old_instance), request, timeout=30.0)
        if not replies or not replies[0][0]:
            detail = replies[0][1].decode(errors="replace") if replies else "no reply"
            raise SystemExit(f"{self.instance}: handover from {old_instance} failed: {detail}")
        handover = msgpack.unpackb(replies[0][1])
        self.core.restore(handover["progress"])
        for leaf, raw in handover["held"].items():
            self.inbox.held[leaf] = decode(raw, VEHICLE_TOPICS[leaf], f"handover {leaf}")
        self.inbox.delivered = dict(handover["delivered"])
        self.started = True
        self.step = resume_step

    # -- the loop -----------------------------------------------------------------------------
    def loop(self) -> int:
        while True:
            mail = self.mailbox.get(timeout=1.0)
            if mail is None:
                if os.getppid() != self.parent:
                    print(f"[{self.instance}] launcher process is gone; exiting", file=sys.stderr)
                    return EXIT_LAUNCHER_GONE
                continue
            if mail.kind == "gone":
                print(f"[{self.instance}] launcher left ({mail.key}); exiting", file=sys.stderr)
                return EXIT_LAUNCHER_GONE
            if mail.kind == "alive":
                continue
            if mail.kind == "query":
                if self.on_control(mail):
                    return 0
                continue
            if mail.key in self.topic_of_key:
                self.on_input(self.topic_of_key[mail.key], mail.payload)
            elif mail.key == keys.tick(self.community):
                tick = self.decode_or_report(mail.payload, Tick, mail.key)
                if tick is not None and self.schedule.runs(self.core.role, tick.step):
                    self.on_tick(tick.step)
            elif mail.key == keys.mission_end(self.community):
                return 0
            self.try_iterate()
            self.try_handover()

    def on_tick(self, step: int) -> None:
        if self.pending is not None:
            self.report_error(f"tick {step} arrived while step {self.pending} is unfinished")
            return
        if not self.started:
            for leaf, message in self.core.startup():
                self.outputs[leaf].put(encode(message))
            self.started = True
        self.pending = step
        self.step = step

    def on_input(self, leaf: str, payload: bytes) -> None:
        message = self.decode_or_report(payload, VEHICLE_TOPICS[leaf], keys.vehicle_topic(self.community, self.vehicle, leaf))
        if message is not None:
            error = self.inbox.offer(leaf, message)
            if error:
                self.report_error(error)

    def try_iterate(self) -> None:
        step = self.pending
        if step is None or self.inbox.waiting_for(step):
            return
        self.core.new_mail(self.inbox.take(step))
        t = step * self.dt
        result = self.core.iterate(step, t)
        for leaf, message in result.outputs:
            self.outputs[leaf].put(encode(message))
        for event in result.events:
            self.event_pub.put(encode(event))
        self.ack_pub.put(encode(Ack(step=step, t=t, source=self.core.role, end=result.end, reason=result.reason)))
        self.pending = None

    # -- control: handover and retire (swap) -------------------------------------------------
    def on_control(self, mail) -> bool:
        """Handle a control query; True means leave the loop."""
        try:
            request = msgpack.unpackb(mail.payload)
            command = request["cmd"]
        except Exception:
            mail.reply_error(f"{self.instance}: control request is not a msgpack map with 'cmd'")
            return False
        if command == "handover":
            self.deferred_handover = (mail, int(request["step"]))
            return False
        if command == "retire":
            mail.reply(msgpack.packb({"ok": True, "instance": self.instance}))
            return True
        mail.reply_error(f"{self.instance}: unknown control command {command!r}")
        return False

    def try_handover(self) -> None:
        if self.deferred_handover is None:
            return
        mail, step = self.deferred_handover
        if self.inbox.waiting_for(step) or self.pending is not None:
            return
        held = {leaf: encode(message) for leaf, message in self.inbox.held.items()}
        reply = {"progress": self.core.progress(), "held": held, "delivered": self.inbox.delivered}
        mail.reply(msgpack.packb(reply))
        self.deferred_handover = None

    # -- reporting ----------------------------------------------------------------------------
    def decode_or_report(self, payload: bytes, model: type[Message], key: str) -> Message | None:
        try:
            return decode(payload, model, key)
        except MessageError as exc:
            self.report_error(f"rejected message: {exc}")
            return None

    def report_error(self, text: str) -> None:
        print(f"[{self.instance}] error: {text}", file=sys.stderr, flush=True)
        event = Event(step=self.step, t=self.step * self.dt, source=self.core.role, kind="error", detail=text)
        self.event_pub.put(encode(event))

    def publish_status(self, state: str) -> None:
        status = AppStatus(
            step=self.step, t=self.step * self.dt, source=self.core.role, app=self.core.role, instance=self.instance, state=state
        )
        self.status_pub.put(encode(status))


def main_for(core_factory, description: str, argv=None) -> int:
    """Entry point shared by the helm, pid and sim processes."""
    args = app_arguments(description).parse_args(argv)
    terminate_on_sigterm()
    try:
        run = load_run(args)
    except MissionError as exc:
        print(f"[{args.instance}] {exc}", file=sys.stderr)
        return 2
    shell = AppShell(core_factory(run.mission), run, args.instance)
    try:
        return shell.serve(args.takeover, args.resume_step)
    except KeyboardInterrupt:
        return 130
