"""The clock app: a thin shell around `runtime.clock.ClockCore`, which grants lock-stepped steps
to the helm, pid and sim and holds every rule.

The clock is off the critical path: it sleeps until mail arrives or until it must act on its own
(a paced step's release time, the stall deadline; `ClockCore.wake_in`), or, while the apps hold
enough granted steps, for a nap in which mail does not wake it (`ClockCore.nap`), then handles all
the mail that is there before deciding, so a burst of outputs costs one wake-up and one decision.

Control requests (messages on nearsub/<community>/control/clock) are answered on the requester's
reply key:
- status: the next step to complete, its simulated time, whether the clock is paused, the warp
  requested and the warp achieved (simulated seconds per wall second over the last 3 s);
- warp: args.warp sets the pacing from the current step on (0: flat out);
- pause: stop granting; answered when the apps have finished the step before the pause, with the
  step at which the mission will resume (args.at: pause before that step instead);
- resume: grant again.
A mission end published by someone else (the launcher, aborting) stops the clock.
"""

from __future__ import annotations

import argparse
import sys
import time

import msgpack

from nearsub.apps.entry import load_run, run_app
from nearsub.apps.shell import wait_for_roles
from nearsub.common.mission.schema import RunConfig
from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Bus, app_endpoints, signal_self
from nearsub.common.runtime.clock import ClockCore, Reply
from nearsub.common.runtime.lifecycle import DONE_TOPIC, ENCOUNTERS
from nearsub.common.runtime.messages import (
    Ack,
    Control,
    MessageError,
    State,
    decode,
    encode,
)
from nearsub.common.runtime.processes import leave


class Clock:
    def __init__(self, run: RunConfig, bus: Bus, after: list[str] = ()):
        mission = self.mission = run.mission
        self.after = list(after)  # services the apps need at step 0 (the surrogate server)
        c = self.community = mission.name
        self.fleet = mission.lockstep()
        observer = None
        if self.fleet.shared:  # checks between the vehicles (numpy: only a fleet's clock imports it)
            from nearsub.common.mission.cores import EncounterCheck

            observer = EncounterCheck(mission)
        self.core = ClockCore(
            self.fleet,
            mission.dt,
            mission.warp,
            mission.max_steps,
            mission.step_timeout,
            mission.pause_at_step,
            observer,
        )
        self.bus = bus
        self.ack_prefix = keys.ack(c, "")
        self.control_key = keys.control(c, "clock")
        self.end_key = keys.mission_end(c)
        # key -> (vehicle, leaf): every vehicle's done topics.
        self.done_topics = {
            keys.vehicle_topic(c, name, leaf): (vehicle, leaf)
            for vehicle, name in zip(self.fleet.vehicles, mission.vehicle_names, strict=True)
            for leaf in DONE_TOPIC.values()
        }
        # The done topics, acks, its control key and the end: not its own ticks, nor other data.
        self.stream = bus.inputs([*self.done_topics, keys.all_acks(c), self.control_key, self.end_key])
        bus.on_liveliness_lost(keys.alive(c, "launcher", "*"), signal_self())
        self.tick_pub = bus.publisher(keys.tick(c))
        self.end_pub = bus.publisher(keys.mission_end(c))
        self.events_pub = bus.publisher(keys.events(c, ENCOUNTERS)) if observer else None
        self.ended = False

    def wait_for_apps(self) -> str | None:
        """Block until every vehicle's helm, pid and sim, and the `after` services, have liveliness
        tokens; an error text on timeout."""
        timeout = self.mission.startup_timeout
        if missing := wait_for_roles(self.bus, self.community, [*self.fleet.runners(0), *self.after], timeout):
            return f"apps did not start within {timeout:g} s: {', '.join(missing)}"
        return None

    def send(self, replies: list[Reply]) -> None:
        for requester, reply in replies:
            self.bus.put_reply(keys.reply(self.community, requester), encode(reply))

    def handle(self, key: str, payload: bytes) -> None:
        """One stream item: progress, a control request, or someone else's mission end."""
        done = self.done_topics.get(key)
        if done is not None:
            self.record_done(*done, payload)
            return
        try:
            if key.startswith(self.ack_prefix):
                vehicle, _ = keys.split_app(key[len(self.ack_prefix) :])
                self.core.progress.record_ack(decode(payload, Ack, key), vehicle)
            elif key == self.control_key:
                self.send(self.core.on_control(decode(payload, Control, key), time.monotonic()))
            elif key == self.end_key:
                self.ended = True
        except MessageError as exc:
            print(f"[clock] error: rejected message: {exc}", file=sys.stderr)

    def record_done(self, vehicle: str | None, leaf: str, payload: bytes) -> None:
        """A done output counts by its source and step label alone, so the clock reads just
        those two fields (a full validation costs about 8 times as much per message); the
        consumers validate and report malformed data. A fleet's clock keeps the states for the
        checks between vehicles, unvalidated too (the sims made them)."""
        try:
            fields = msgpack.unpackb(payload)
            role, label = fields["source"], fields["step"]
        except Exception:  # not msgpack, not a map, no such field: a consumer reports it
            return
        if isinstance(role, str) and isinstance(label, int) and not isinstance(label, bool):
            self.core.progress.record_output(leaf, role, label, vehicle)
            if leaf == "state" and self.events_pub is not None:
                self.core.record_state(vehicle, label, State.model_construct(**fields))

    def run(self) -> int:
        error = self.wait_for_apps()
        if error:
            self.end_pub.put(encode(self.core.mission_end(0, "error", error)))
            print(f"[clock] {error}", file=sys.stderr)
            return 1
        self.core.start(time.monotonic())
        while not self.ended:
            advance = self.core.advance(time.monotonic())
            for event in advance.events:
                self.events_pub.put(encode(event))
            self.send(advance.replies)
            if advance.end is not None:
                self.end_pub.put(encode(advance.end))
                if advance.end.outcome == "stalled":
                    print(f"[clock] stalled: {advance.end.reason}", file=sys.stderr)
                    return 1
                return 0
            if advance.tick is not None:
                self.tick_pub.put(encode(advance.tick))
            now = time.monotonic()
            nap = self.core.nap(now)
            if nap > 0:
                time.sleep(nap)
                item = self.stream.try_recv()
            else:
                item = self.stream.try_recv(self.core.wake_in(now))
            while item is not None:
                self.handle(*item)
                item = self.stream.try_recv()
        return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="nearsub lock-stepped clock")
    parser.add_argument("--run", required=True)
    parser.add_argument("--instance", default="clock")
    parser.add_argument(
        "--after", action="append", default=[], metavar="ROLE", help="wait for this role's liveliness token too"
    )
    return run_app(parser, serve, argv)


def serve(args) -> int:
    run = load_run(args.run)
    with Bus(app_endpoints(run.connect)) as bus:
        clock = Clock(run, bus, args.after)
        bus.token(keys.alive(run.mission.name, "clock", args.instance))
        return clock.run()


if __name__ == "__main__":
    leave(main())
