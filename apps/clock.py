"""The clock app: lock-stepped ticks for the helm, pid and sim (common/clock.py has the rules).

Control requests arrive as queries on nearsub/<community>/clock/control (msgpack maps):
- {"cmd": "status"}: the current step and whether the clock is paused;
- {"cmd": "pause"}: answered once the current step is complete, with the next step to run;
- {"cmd": "resume"}: continue ticking.
A MissionEnd published by someone else (the launcher aborting) stops the clock.
"""

from __future__ import annotations

import argparse
import sys
import time

import msgpack

from nearsub.apps.shell import terminate_on_sigterm
from nearsub.common import keys
from nearsub.common.bus import Bus, Endpoints, Mailbox
from nearsub.common.clock import Pacer, StepBarrier
from nearsub.common.lifecycle import ORDER, Schedule
from nearsub.common.messages import Ack, MessageError, MissionEnd, Tick, decode, encode
from nearsub.common.mission import RunConfig


class Clock:
    def __init__(self, run: RunConfig, instance: str, bus: Bus):
        mission = run.mission
        self.mission = mission
        self.community = mission.name
        self.instance = instance
        self.schedule = Schedule(mission.periods())
        self.pacer = Pacer(mission.dt, mission.warp)
        self.bus = bus
        self.mailbox = Mailbox()
        c = self.community
        bus.subscribe(keys.acks(c), self.mailbox)
        bus.subscribe(keys.mission_end(c), self.mailbox)
        bus.queryable(keys.clock_control(c), self.mailbox)
        self.tick_pub = bus.publisher(keys.tick(c))
        self.end_pub = bus.publisher(keys.mission_end(c))
        self.step = 0
        self.paused = False
        self.pause_requests = []
        self.aborted = False

    def wait_for_apps(self) -> str | None:
        """Block until helm, pid and sim have liveliness tokens; an error text on timeout."""
        deadline = time.monotonic() + self.mission.startup_timeout
        while True:
            alive = self.bus.alive(keys.all_alive(self.community), timeout=0.5)
            roles = {key.split("/")[3] for key in alive}
            missing = [role for role in ORDER if role not in roles]
            if not missing:
                return None
            if time.monotonic() > deadline:
                return f"apps did not start within {self.mission.startup_timeout:g} s: {', '.join(missing)}"
            time.sleep(0.02)

    def finish(self, step: int, outcome: str, reason: str) -> None:
        end = MissionEnd(step=step, t=step * self.mission.dt, source="clock", outcome=outcome, reason=reason)
        self.end_pub.put(encode(end))

    def handle(self, mail, barrier: StepBarrier | None) -> None:
        """Process one mailbox item while waiting for acks or for the release time."""
        if mail.kind == "query":
            self.on_control(mail)
        elif mail.key == keys.mission_end(self.community):
            self.aborted = True
        elif barrier is not None:
            try:
                ack = decode(mail.payload, Ack, mail.key)
            except MessageError as exc:
                print(f"[clock] error: rejected message: {exc}", file=sys.stderr)
                return
            error = barrier.record(ack)
            if error:
                print(f"[clock] error: {error}", file=sys.stderr)

    def on_control(self, mail) -> None:
        try:
            command = msgpack.unpackb(mail.payload)["cmd"]
        except Exception:
            mail.reply_error("clock: control request is not a msgpack map with 'cmd'")
            return
        if command == "status":
            mail.reply(msgpack.packb({"step": self.step, "paused": self.paused}))
        elif command == "pause":
            self.pause_requests.append(mail)
        elif command == "resume":
            self.paused = False
            self.pacer.rebase(time.monotonic(), self.step)
            mail.reply(msgpack.packb({"step": self.step}))
        else:
            mail.reply_error(f"clock: unknown command {command!r}")

    def serve_pause_requests(self) -> None:
        """Answer pause requests; only called between steps, so the reply names the next step."""
        for mail in self.pause_requests:
            self.paused = True
            mail.reply(msgpack.packb({"step": self.step}))
        self.pause_requests.clear()

    def run(self) -> int:
        error = self.wait_for_apps()
        if error:
            self.finish(0, "error", error)
            print(f"[clock] {error}", file=sys.stderr)
            return 1
        self.pacer.rebase(time.monotonic(), 0)
        max_steps = self.mission.max_steps
        while not self.aborted:
            # Step boundary: serve pause requests, then wait while paused or until release time.
            self.serve_pause_requests()
            while not self.aborted and (self.paused or time.monotonic() < self.pacer.release_time(self.step)):
                timeout = None if self.paused else max(0.0, self.pacer.release_time(self.step) - time.monotonic())
                mail = self.mailbox.get(timeout=timeout if timeout is None else min(timeout, 0.5))
                if mail is not None:
                    self.handle(mail, None)
                    self.serve_pause_requests()
            if self.aborted:
                break
            step = self.step
            barrier = StepBarrier.for_step(self.schedule, step)
            self.tick_pub.put(encode(Tick(step=step, t=step * self.mission.dt, source="clock")))
            deadline = time.monotonic() + self.mission.step_timeout
            while barrier.missing and not self.aborted:
                mail = self.mailbox.get(timeout=max(0.0, deadline - time.monotonic()))
                if mail is None:
                    reason = barrier.stall_reason(self.mission.step_timeout)
                    print(f"[clock] stalled: {reason}", file=sys.stderr)
                    self.finish(step, "stalled", reason)
                    return 1
                self.handle(mail, barrier)
            if self.aborted:
                break
            self.step = step + 1
            if barrier.end is not None:
                self.finish(self.step, barrier.end, barrier.reason)
                return 0
            if self.step >= max_steps:
                self.finish(self.step, "time_limit", f"reached the time limit of {self.mission.time_limit:g} s")
                return 0
        return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="nearsub lock-stepped clock")
    parser.add_argument("--run", required=True)
    parser.add_argument("--instance", default="clock")
    args = parser.parse_args(argv)
    terminate_on_sigterm()
    run = RunConfig.load(args.run)
    try:
        with Bus(Endpoints("client", tuple(run.connect))) as bus:
            clock = Clock(run, args.instance, bus)
            bus.token(keys.alive(run.mission.name, "clock", args.instance))
            return clock.run()
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
