"""What a launch tells people: progress lines on stderr (not with --json), on a terminal a status
line rewritten each STATUS_INTERVAL, and the summary at the end (text or JSON) with its exit code."""

from __future__ import annotations

import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from nearsub.common.runtime.messages import Event, MessageError, MissionEnd, decode, model_for_key

if TYPE_CHECKING:
    from nearsub.common.analysis.approach import Approaches

NORMAL_OUTCOMES = ("completed", "time_limit", "collision")
STATUS_INTERVAL = 1.0  # wall seconds between two updates of the terminal status line


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
    approaches: Approaches | None = None  # closest to the hull and between UUVs, from the log

    def record_end(self, end: MissionEnd) -> None:
        """The mission end's step, time, outcome and reason. An interrupt always wins: an app's
        normal end can still be in the launcher's mailbox, or on its way, when Ctrl-C stops the
        mission, and it must not turn the launch's exit 130 into 0."""
        self.steps, self.sim_time = end.step, end.t
        if self.outcome != "interrupted":
            self.outcome, self.reason = end.outcome, end.reason

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
            **({"approaches": self.approaches.as_dict()} if self.approaches else {}),
        }

    def text(self) -> str:
        """The summary for people; a mission stopped before it ran is its first line only."""
        if self.outcome == "interrupted" and not self.startup_time:
            return f"mission {self.community}: interrupted ({self.reason})"
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
        lines += [f"  {line}" for line in (self.approaches.lines() if self.approaches else ())]
        if self.swaps:
            lines.append("  swaps: " + "; ".join(f"{s['old']} -> {s['new']} at step {s['step']}" for s in self.swaps))
        if self.log:
            lines.append(f"  log {self.log}")
        return "\n".join(lines)


def interrupted_reason(summary: Summary) -> str:
    """Why a mission stopped on Ctrl-C (or SIGTERM): before every app was up, or while it ran."""
    return "stopped by the user" + ("" if summary.startup_time else " during start-up")


def exit_code(summary: Summary) -> int:
    if summary.outcome in NORMAL_OUTCOMES:
        return 0
    return 130 if summary.outcome == "interrupted" else 1


class Console:
    """The launcher's lines for people: `say` (progress, on stderr), `event` (a mission event worth
    reading) and, when stdout is a terminal, the status line."""

    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.status_line = not quiet and sys.stdout.isatty()
        self.next_status = 0.0
        self.showing_status = False
        self.launched = time.monotonic()
        self.positions: dict[str, tuple] = {}  # vehicle -> (u, x, y), from the latest states
        self.phases: dict[str, dict] = {}  # vehicle -> what its helm last said it was doing

    def say(self, text: str) -> None:
        """A progress line for people (not with --json)."""
        if not self.quiet:
            self.clear_status()
            print(f"[launch {time.monotonic() - self.launched:5.2f} s] {text}", file=sys.stderr, flush=True)

    def event(self, event: Event, vehicle: str | None) -> None:
        """A waypoint, collision, swap or error, as it happens (not with --json)."""
        if not self.quiet and event.kind in ("waypoint", "collision", "swap", "error"):
            self.clear_status()
            who = f"{vehicle}: " if vehicle else ""
            print(f"  t={event.t:8.2f}  {event.kind:<10} {who}{event.detail}", file=sys.stderr, flush=True)

    def helm_phases(self, progress, fleet: bool) -> None:
        """A line for each change of what a helm does (its behaviour, its MODE, the behaviours
        with an objective, completion), from `progress`, a stream of the helms' progress (None
        with --json)."""
        while progress is not None and (latest := progress.try_recv()) is not None:
            key, payload = latest
            try:
                message = decode(payload, model_for_key(key), key)
            except MessageError:
                continue
            vehicle = key.split("/")[2]
            now = {
                "helm": message.behaviour,
                "mode": message.mode,
                "active": ", ".join(message.active) or "none",
                "complete": message.complete,
            }
            before = self.phases.get(vehicle)
            self.phases[vehicle] = now
            if before is None:
                changed = [f"mode {now['mode']}"] * bool(now["mode"]) + [f"active {now['active']}"]
            else:
                changed = [f"{name} {now[name]}" for name in ("helm", "mode", "active") if now[name] != before[name]]
                changed += ["complete"] * (now["complete"] and not before["complete"])
            if changed:
                self.clear_status()
                who = f"{vehicle}: " if fleet else ""
                print(f"  t={message.t:8.2f}  {'phase':<10} {who}{'; '.join(changed)}", file=sys.stderr, flush=True)

    def status_due(self) -> bool:
        return self.status_line and time.monotonic() >= self.next_status

    def show_status(self, caller, states, fleet: bool) -> None:
        """One terminal line, rewritten each STATUS_INTERVAL: the clock's step, simulated time and
        achieved warp (against the requested one), from its `caller` status, the vehicle's speed and
        position from the latest of `states` (a stream of the vehicles' states)."""
        self.next_status = time.monotonic() + STATUS_INTERVAL
        reply = caller.call("clock", "status", timeout=0.5)
        if reply is None or not reply.ok:
            return
        status = reply.data
        achieved = status.get("achieved_warp")
        warp = f"warp {'-' if achieved is None else f'{achieved:.1f}'}"
        if status["warp"] > 0:
            warp += f" of {status['warp']:g}"
        line = f"t {status['t']:8.2f} s  step {status['step']:>6}  {warp}"
        while (latest := states.try_recv()) is not None:
            try:
                state = decode(latest[1], model_for_key(latest[0]), latest[0])
            except MessageError:
                continue
            self.positions[latest[0].split("/")[2]] = (state.u, state.x, state.y)
        if not fleet and self.positions:
            u, x, y = next(iter(self.positions.values()))
            line += f"  u {u:5.2f} m/s  at ({x:8.2f}, {y:8.2f})"
        for vehicle, (u, x, y) in sorted(self.positions.items()) if fleet else ():
            line += f"  {vehicle} {u:.1f} m/s ({x:.0f}, {y:.0f})"
        sys.stdout.write(f"\r\033[K{line}")
        sys.stdout.flush()
        self.showing_status = True

    def clear_status(self) -> None:
        if self.showing_status:
            sys.stdout.write("\r\033[K")
            sys.stdout.flush()
            self.showing_status = False
