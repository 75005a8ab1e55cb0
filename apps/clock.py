"""The clock app: grants lock-stepped steps to the helm, pid and sim (common/clock.py has the rules).

The clock is off the critical path: it drains its stream in batches (a short sleep between
polls), so it wakes a few hundred times a second rather than once per message.

Control requests (messages on nearsub/<community>/control/clock) are answered on the requester's
reply key:
- status: the next step to complete and whether the clock is paused;
- pause: stop granting; answered when the apps have finished the step before the pause, with the
  step at which the mission will resume (args.at: pause before that step instead);
- resume: grant again.
A mission end published by someone else (the launcher, aborting) stops the clock.
"""

from __future__ import annotations

import argparse
import sys
import time

from nearsub.apps.shell import prepare_process
from nearsub.common.mission.schema import RunConfig
from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Bus, Endpoints, signal_self
from nearsub.common.runtime.clock import GrantPolicy, Progress
from nearsub.common.runtime.lifecycle import DONE_TOPIC, ORDER, Schedule
from nearsub.common.runtime.messages import (
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

POLL = 0.002  # seconds between stream polls while the apps work (the grant window covers it)
IDLE_POLL = 0.01  # while paused or waiting for the warp's release time


class Clock:
    def __init__(self, run: RunConfig, bus: Bus):
        mission = self.mission = run.mission
        c = self.community = mission.name
        self.progress = Progress(Schedule(mission.periods()))
        self.policy = GrantPolicy(mission.dt, mission.warp, mission.max_steps)
        self.bus = bus
        self.stream = bus.stream(keys.everything(c))
        bus.on_liveliness_lost(keys.alive(c, "launcher", "*"), signal_self())
        self.tick_pub = bus.publisher(keys.tick(c))
        self.end_pub = bus.publisher(keys.mission_end(c))
        self.ack_prefix = keys.ack(c, "")
        self.control_key = keys.control(c, "clock")
        self.end_key = keys.mission_end(c)
        self.done_topics = {keys.vehicle_topic(c, mission.vehicle_name, leaf): leaf for leaf in DONE_TOPIC.values()}
        self.granted = -1
        self.pause_before: int | None = mission.pause_at_step
        self.pause_requests: list[Control] = []
        self.paused = False
        self.ended = False

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

    @property
    def step(self) -> int:
        """The next step to complete."""
        return self.progress.completed + 1

    def finish(self, step: int, outcome: str, reason: str) -> None:
        end = MissionEnd(step=step, t=step * self.mission.dt, source="clock", outcome=outcome, reason=reason)
        self.end_pub.put(encode(end))
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

    def handle(self, key: str, payload: bytes) -> None:
        """One stream item: progress, a control request, or someone else's mission end."""
        leaf = self.done_topics.get(key)
        try:
            if leaf is not None:
                self.progress.record_output(leaf, decode(payload, VEHICLE_TOPICS[leaf], key))
            elif key.startswith(self.ack_prefix):
                self.progress.record_ack(decode(payload, Ack, key))
            elif key == self.control_key:
                self.on_control(decode(payload, Control, key))
            elif key == self.end_key:
                self.ended = True
        except MessageError as exc:
            if leaf is None:  # consumers report malformed data; the clock only reports its own mail
                print(f"[clock] error: rejected message: {exc}", file=sys.stderr)

    def on_control(self, request: Control) -> None:
        if request.cmd == "status":
            self.reply(request, step=self.step, paused=self.paused)
        elif request.cmd == "pause":
            at = int(request.args.get("at", self.granted + 1))
            if at <= self.granted:
                self.reply(
                    request, ok=False, error=f"step {at} has passed or is granted (granted up to {self.granted})"
                )
                return
            self.pause_before = at if self.pause_before is None else min(self.pause_before, at)
            self.pause_requests.append(request)
        elif request.cmd == "resume":
            self.paused = False
            self.pause_before = None
            self.policy.rebase(time.monotonic(), self.step)
            self.reply(request, step=self.step)
        else:
            self.reply(request, ok=False, error=f"clock: unknown command {request.cmd!r}")

    def run(self) -> int:
        error = self.wait_for_apps()
        if error:
            self.finish(0, "error", error)
            print(f"[clock] {error}", file=sys.stderr)
            return 1
        self.policy.rebase(time.monotonic(), 0)
        timeout = self.mission.step_timeout
        last_completed, last_progress = -1, time.monotonic()
        while not self.ended:
            while (item := self.stream.try_recv()) is not None:
                self.handle(*item)
            now = time.monotonic()
            completed, end = self.progress.completed, self.progress.end
            if completed != last_completed:
                last_completed, last_progress = completed, now
            if end is not None and completed >= end.step:
                self.finish(end.step + 1, end.outcome, end.reason)
                return 0
            if completed >= self.mission.max_steps - 1:
                self.finish(
                    self.mission.max_steps, "time_limit", f"reached the time limit of {self.mission.time_limit:g} s"
                )
                return 0
            if self.pause_before is not None and completed == self.pause_before - 1:
                self.paused = True
            if self.paused:  # answer the requests due now, also those that came after the pause began
                due = [r for r in self.pause_requests if int(r.args.get("at", self.step)) <= self.step]
                for request in due:
                    self.reply(request, step=self.step)
                    self.pause_requests.remove(request)
            if not self.paused:
                self.grant(completed, now)
            if self.granted > completed and now - last_progress > timeout:
                reason = self.progress.stall_reason(timeout)
                print(f"[clock] stalled: {reason}", file=sys.stderr)
                self.finish(completed + 1, "stalled", reason)
                return 1
            time.sleep(POLL if self.granted > completed else IDLE_POLL)
        return 0

    def grant(self, completed: int, now: float) -> None:
        """Extend the grant in chunks of half the window (fewer ticks), or up to a cap."""
        limit = self.policy.limit(completed, now, self.pause_before, self.progress.end)
        if limit > self.granted and (
            limit - self.granted >= self.policy.window // 2 or limit - completed < self.policy.window
        ):
            self.granted = limit
            self.tick_pub.put(encode(Tick(step=limit, t=limit * self.mission.dt, source="clock")))


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
