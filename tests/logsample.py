"""A small mission log written the way the logger writes it, for the log tools' tests: the alpha
mission run in-process for a few seconds, its messages under the mission's keys."""

from __future__ import annotations

import random
from pathlib import Path

from conftest import ALPHA
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.logfile import LogWriter
from nearsub.common.runtime.messages import Control, Event, MissionEnd, State, encode

STARTED_UNIX = 1_800_000_000.25  # the logger's start time written as run metadata


def write_sample_log(path: Path, seconds: float = 10.0, shuffle: bool = False):
    """Run alpha for `seconds` and log it at `path`; with `shuffle` the records reach the file out
    of time order (as a busy logger receives them). Returns the in-process result."""
    mission = load_mission(ALPHA, [f"time_limit={seconds:g}"])
    result = run_mission(mission)
    entries = []
    for role, leaf, message in result.messages:
        key = f"nearsub/alpha/events/{role}" if leaf == "events" else f"nearsub/alpha/remus100/{leaf}"
        entries.append((key, encode(message), message.t))
    pause = Control(step=40, t=2.0, source="tap", cmd="pause", request_id="r1", reply_to="nearsub/alpha/reply/tap")
    entries.append(("nearsub/alpha/control/clock", encode(pause), 2.0))
    if shuffle:
        random.Random(7).shuffle(entries)
    writer = LogWriter(path)
    writer.metadata("mission", {"name": "alpha", "resolved": mission.model_dump_json()})
    writer.metadata("run", {"started_unix": f"{STARTED_UNIX:.3f}"})
    for key, data, t in entries:
        writer.write(key, data, t)
    writer.write("nearsub/alpha/remus100/state", b"\xc1", seconds, valid=False)
    writer.finish()
    return result


FLEET = {"alfa": 0.0, "bravo": 30.0}  # vehicle name -> its offset in y [m] from the alpha run


def write_fleet_log(path: Path, seconds: float = 10.0):
    """A two-vehicle log: the alpha run of `write_sample_log` flown by "alfa" and, 30 m to its
    +y side, by "bravo", each under its own vehicle keys nearsub/alpha/<name>/<leaf>; the
    events of "bravo" come from its apps (nearsub/alpha/events/bravo/<role>-1), those of "alfa"
    from mission-wide instances (nearsub/alpha/events/<role>).
    "bravo" stops half-way (a shorter time span). Returns the in-process result."""
    mission = load_mission(ALPHA, [f"time_limit={seconds:g}"])
    result = run_mission(mission)
    writer = LogWriter(path)
    writer.metadata("mission", {"name": "alpha", "resolved": mission.model_dump_json()})
    writer.metadata("run", {"started_unix": f"{STARTED_UNIX:.3f}"})
    for name, dy in FLEET.items():
        for role, leaf, message in result.messages:
            if name == "bravo" and message.t > seconds / 2:
                continue
            if leaf == "events":
                key = f"nearsub/alpha/events/{role}" if name == "alfa" else f"nearsub/alpha/events/{name}/{role}-1"
            else:
                key = f"nearsub/alpha/{name}/{leaf}"
            if isinstance(message, State):
                message = message.model_copy(update={"y": message.y + dy})
            elif isinstance(message, Event) and "y" in message.data:
                message = message.model_copy(update={"data": message.data | {"y": message.data["y"] + dy}})
            writer.write(key, encode(message), message.t)
    end = MissionEnd(step=result.steps, t=seconds, source="clock", outcome=result.outcome, reason=result.reason)
    writer.write("nearsub/alpha/clock/end", encode(end), seconds)
    writer.finish()
    return result
