"""The clock app: lock-stepped ticks for the helm, pid and sim (common/clock.py has the rules).

Control requests (messages on nearsub/<community>/control/clock) are answered on the requester's
reply key:
- status: the current step and whether the clock is paused;
- pause: answered once the current step is complete, with the next step to run;
- resume: continue ticking.
A mission end published by someone else (the launcher, aborting) stops the clock.
"""

from __future__ import annotations

import argparse
import sys
import time

from nearsub.apps.shell import prepare_process
from nearsub.common import keys
from nearsub.common.bus import Bus, DeadlineExceeded, Endpoints, deadline, signal_self
from nearsub.common.clock import Pacer, StepBarrier
from nearsub.common.lifecycle import DONE_TOPIC, ORDER, Schedule
from nearsub.common.messages import (
    VEHICLE_TOPICS,
    Ack,
    Control,
    ControlReply,
    MessageError,
    MissionEnd,
    Tick,
    decode,
    encode,
)
from nearsub.common.mission import RunConfig


class Clock:
    def __init__(self, run: RunConfig, bus: Bus):
        mission = self.mission = run.mission
        c = self.community = mission.name
        self.schedule = Schedule(mission.periods())
        self.pacer = Pacer(mission.dt, mission.warp)
        self.bus = bus
        self.stream = bus.stream(keys.everything(c))
        bus.on_liveliness_lost(keys.alive(c, "launcher", "*"), signal_self())
        self.tick_pub = bus.publisher(keys.tick(c))
        self.end_pub = bus.publisher(keys.mission_end(c))
        self.ack_prefix = keys.ack(c, "")
        self.done_topics = {keys.vehicle_topic(c, mission.vehicle_name, leaf): leaf for leaf in DONE_TOPIC.values()}
        self.control_key = keys.control(c, "clock")
        self.end_key = keys.mission_end(c)
        self.step = 0
        self.paused = False
        self.pause_requests: list[Control] = []
        self.ended = False
        self.pause_at_step_done = False

    def wait_for_apps(self) -> str | None:
        """Block until helm, pid and sim have liveliness tokens; an error text on timeout."""
        end = time.monotonic() + self.mission.startup_timeout
        while True:
            alive = self.bus.alive(keys.all_alive(self.community), timeout=0.5)
            roles = {key.split("/")[3] for key in alive}
            missing = [role for role in ORDER if role not in roles]
            if not missing:
                return None
            if time.monotonic() > end:
                return f"apps did not start within {self.mission.startup_timeout:g} s: {', '.join(missing)}"
            time.sleep(0.02)

    def finish(self, step: int, outcome: str, reason: str) -> None:
        self.end_pub.put(
            encode(MissionEnd(step=step, t=step * self.mission.dt, source="clock", outcome=outcome, reason=reason))
        )
        self.ended = True

    def reply(self, request: Control, ok: bool = True, error: str = "", **data) -> None:
        answer = ControlReply(
            step=self.step,
            t=self.step * self.mission.dt,
            source="clock",
            request_id=request.request_id,
            ok=ok,
            data=data,
            error=error,
        )
        self.bus.put_when_matched(keys.reply(self.community, request.reply_to), encode(answer))

    def handle(self, key: str, payload: bytes, barrier: StepBarrier | None) -> None:
        """One stream item, while waiting for acks (barrier) or between steps (None)."""
        leaf = self.done_topics.get(key)
        if leaf is not None:
            if barrier is not None:
                try:
                    barrier.record_output(leaf, decode(payload, VEHICLE_TOPICS[leaf], key))
                except MessageError:
                    pass  # the consumers report malformed data; the clock only counts
        elif key.startswith(self.ack_prefix):
            if barrier is None:
                print(f"[clock] error: ack outside a step from {key}", file=sys.stderr)
                return
            try:
                error = barrier.record(decode(payload, Ack, key))
            except MessageError as exc:
                error = f"rejected message: {exc}"
            if error:
                print(f"[clock] error: {error}", file=sys.stderr)
        elif key == self.control_key:
            try:
                self.on_control(decode(payload, Control, key))
            except MessageError as exc:
                print(f"[clock] error: rejected message: {exc}", file=sys.stderr)
        elif key == self.end_key:
            self.ended = True  # someone else (the launcher) ended the mission

    def on_control(self, request: Control) -> None:
        if request.cmd == "status":
            self.reply(request, step=self.step, paused=self.paused)
        elif request.cmd == "pause":
            at = request.args.get("at")
            if at is not None and int(at) < self.step:
                self.reply(request, ok=False, error=f"step {at} has passed (the clock is at step {self.step})")
            else:
                self.pause_requests.append(request)
        elif request.cmd == "resume":
            self.paused = False
            self.pacer.rebase(time.monotonic(), self.step)
            self.reply(request, step=self.step)
        else:
            self.reply(request, ok=False, error=f"clock: unknown command {request.cmd!r}")

    def serve_pause_requests(self) -> None:
        """Answer the pause requests due at this step; only called between steps, so the reply
        names the next step to run. The mission's pause_at_step pauses without a request."""
        if self.mission.pause_at_step == self.step and not self.pause_at_step_done:
            self.paused = self.pause_at_step_done = True
        due = [r for r in self.pause_requests if int(r.args.get("at", self.step)) <= self.step]
        for request in due:
            self.paused = True
            self.reply(request, step=self.step)
            self.pause_requests.remove(request)

    def between_steps(self) -> None:
        """Serve control and wait while paused or until the warp's release time."""
        self.serve_pause_requests()
        while not self.ended:
            while (item := self.stream.try_recv()) is not None:
                self.handle(*item, None)
                self.serve_pause_requests()
            if self.paused:
                self.handle(*self.stream.recv(), None)
                self.serve_pause_requests()
                continue
            wait = self.pacer.release_time(self.step) - time.monotonic()
            if wait <= 0:
                return
            time.sleep(min(wait, 0.05))

    def run(self) -> int:
        error = self.wait_for_apps()
        if error:
            self.finish(0, "error", error)
            print(f"[clock] {error}", file=sys.stderr)
            return 1
        self.pacer.rebase(time.monotonic(), 0)
        timeout = self.mission.step_timeout
        while True:
            self.between_steps()
            if self.ended:
                return 0
            step = self.step
            barrier = StepBarrier.for_step(self.schedule, step)
            self.tick_pub.put(encode(Tick(step=step, t=step * self.mission.dt, source="clock")))
            try:
                with deadline(timeout):
                    while barrier.missing and not self.ended:
                        self.handle(*self.stream.recv(), barrier)
            except DeadlineExceeded:
                reason = barrier.stall_reason(timeout)
                print(f"[clock] stalled: {reason}", file=sys.stderr)
                self.finish(step, "stalled", reason)
                return 1
            if self.ended:
                return 0
            self.step = step + 1
            if barrier.end is not None:
                self.finish(self.step, barrier.end, barrier.reason)
                return 0
            if self.step >= self.mission.max_steps:
                self.finish(self.step, "time_limit", f"reached the time limit of {self.mission.time_limit:g} s")
                return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="nearsub lock-stepped clock")
    parser.add_argument("--run", required=True)
    parser.add_argument("--instance", default="clock")
    args = parser.parse_args(argv)
    prepare_process()
    run = RunConfig.load(args.run)
    try:
        with Bus(Endpoints("client", tuple(run.connect))) as bus:
            clock = Clock(run, bus)
            bus.token(keys.alive(run.mission.name, "clock", args.instance))
            return clock.run()
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
