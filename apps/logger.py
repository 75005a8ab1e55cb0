"""The logger app (pLogger): records every message of the community into one MCAP file.

It stores the bytes exactly as received, timestamped by simulated time (control requests and
operator overrides, sent with t = 0, at the simulated time they arrived: `Recorder.log_time`). A payload that fails
validation is kept on a `<key>#invalid` channel and an error event is recorded, so nothing is
lost and the typed channels stay clean. A flood of invalid messages cannot grow the log without
bound: the first INVALID_KEPT of each key are kept, the rest only counted, and the counts go into
the log's `invalid_dropped` metadata (`nearsub log info` shows them). It finishes the file on
every way out: the mission end, SIGINT/SIGTERM, or the launcher disappearing.
"""

from __future__ import annotations

import argparse
import queue
import sys
import time
from collections import Counter
from pathlib import Path

from nearsub import __version__
from nearsub.apps.entry import load_run, run_app
from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Bus, app_endpoints, queue_lost, signal_self
from nearsub.common.runtime.lifecycle import OPERATOR
from nearsub.common.runtime.logfile import LogWriter
from nearsub.common.runtime.messages import (
    AppStatus,
    Control,
    Event,
    MessageError,
    MissionEnd,
    decode,
    encode,
    model_for_key,
)
from nearsub.common.runtime.processes import leave

DRAIN_SECONDS = 0.3  # after the last app has left, keep what is still in flight (app_left)
# Wall seconds between two reads of an empty stream: about 50 messages at 1000 steps/s, far below
# the stream's capacity (bus.stream), so the publishers never wait on the logger.
NAP = 0.02
INVALID_KEPT = 100  # invalid messages kept per key (each with its error event); the rest are counted


class Recorder:
    def __init__(self, writer: LogWriter, community: str):
        self.writer = writer
        self.community = community
        self.sim_time = 0.0
        self.end: MissionEnd | None = None
        self.running: set[str] = set()  # liveliness keys of the apps that said "running", not yet "stopping"
        self.invalid: Counter[str] = Counter()  # invalid messages seen per key, kept or not

    def log_time(self, message) -> float:
        """The simulated time a message is logged at: its own t, except for requests from outside
        the lock-step (control requests: pause, resume, warp, handover; an operator's override),
        which carry t = 0 whenever they are sent: they are logged at the simulated time the mission
        had reached when they arrived (the newest t seen), so a log shows them where they happened."""
        if isinstance(message, Control) or message.source == OPERATOR:
            return max(message.t, self.sim_time)
        return message.t

    def dropped(self) -> dict[str, str]:
        """Invalid messages counted but not kept, per key (metadata values are strings)."""
        return {key: str(n - INVALID_KEPT) for key, n in sorted(self.invalid.items()) if n > INVALID_KEPT}

    def record(self, key: str, payload: bytes) -> None:
        model = model_for_key(key)
        if model is None:
            self.writer.write(key, payload, self.sim_time)
            return
        try:
            message = decode(payload, model, key)
        except MessageError as exc:
            self.invalid[key] += 1
            if self.invalid[key] > INVALID_KEPT:
                return
            self.writer.write(key, payload, self.sim_time, valid=False)
            detail = f"logger received an invalid message: {exc}"
            if self.invalid[key] == INVALID_KEPT:
                detail += f" (the last kept of {key}: further invalid messages are only counted)"
            error = Event(step=0, t=self.sim_time, source="logger", kind="error", detail=detail)
            self.writer.write(keys.events(self.community, "logger"), encode(error), self.sim_time)
            return
        self.sim_time = max(self.sim_time, message.t)
        self.writer.write(key, payload, self.log_time(message))
        if isinstance(message, MissionEnd) and self.end is None:
            self.end = message
        elif isinstance(message, AppStatus):
            token = keys.alive(self.community, message.app, message.instance)
            (self.running.add if message.state == "running" else self.running.discard)(token)


def drain(stream, recorder: Recorder, nap: float = 0.01) -> None:
    """Record the next message, or nap when none is waiting."""
    item = stream.try_recv()
    if item is None:
        time.sleep(nap)
    else:
        recorder.record(*item)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="nearsub logger")
    parser.add_argument("--run", required=True)
    parser.add_argument("--instance", default="logger")
    parser.add_argument("--output", required=True, help="MCAP file to write")
    parser.add_argument("--mission-file", help="mission file to attach")
    return run_app(parser, record, argv)


def record(args) -> int:
    """Record the mission of the run file `args.run` until its end (then its apps' last words)."""
    run = load_run(args.run)
    community = run.mission.name
    writer = LogWriter(args.output)
    writer.metadata("mission", {"name": community, "resolved": run.mission.model_dump_json()})
    writer.metadata("run", {"nearsub_version": __version__, "started_unix": f"{time.time():.3f}"})
    if args.mission_file and Path(args.mission_file).is_file():
        text = Path(args.mission_file).read_bytes()
        writer.metadata("mission_file", {"path": args.mission_file, "toml": text.decode(errors="replace")})
        writer.attach(Path(args.mission_file).name, text, "application/toml")
    recorder = Recorder(writer, community)
    try:
        with Bus(app_endpoints(run.connect)) as bus:
            stream = bus.stream(keys.everything(community))
            bus.on_liveliness_lost(keys.alive(community, "launcher", "*"), signal_self())
            lost: queue.SimpleQueue[str] = queue.SimpleQueue()
            bus.on_liveliness_lost(keys.all_alive(community), queue_lost(lost))
            bus.token(keys.alive(community, "logger", args.instance))
            while recorder.end is None:  # read in batches: a wake-up per message cost more than the rest
                drain(stream, recorder, NAP)
            # An app may still be finishing the end step's follow-up work (the sim's forces at the
            # last state, `Iteration.then`): keep recording until every app has said "stopping"
            # (its last words, after its last outputs, on the same link) or has gone (died), for
            # at most one step timeout, then what is still in flight.
            give_up = time.monotonic() + run.mission.step_timeout
            while recorder.running and time.monotonic() < give_up:
                drain(stream, recorder)
                while not lost.empty():
                    recorder.running.discard(lost.get())
            drain_until = time.monotonic() + DRAIN_SECONDS
            while time.monotonic() < drain_until:
                drain(stream, recorder)
    finally:  # also on a lost router, Ctrl-C or SIGTERM (the launcher's, or the lost-launcher watch)
        end = recorder.end
        if end is not None:
            writer.metadata(
                "outcome", {"outcome": end.outcome, "reason": end.reason, "steps": str(end.step), "t": f"{end.t:g}"}
            )
        if dropped := recorder.dropped():
            writer.metadata("invalid_dropped", dropped)
        writer.finish()
        print(f"[logger] wrote {writer.count} messages to {writer.path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    leave(main())
