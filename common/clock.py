"""The lock-stepped clock's protocol, free of transport (SPEC section 4).

For each step the clock publishes a tick, then waits until every app the schedule runs at that
step has acknowledged it. An app acknowledges a step by publishing its done-topic output for it
(lifecycle.DONE_TOPIC: the helm's desired state, the pid's input, the sim's next state), or with
an explicit Ack when it asks to end the mission. It never moves on with a missing acknowledgement: past `step_timeout`
it ends the mission naming the stalled app. Apps later in the thesis loop wait on earlier ones,
so the first missing app in loop order is the one that stalled.

Time warp paces the ticks against the wall clock: step k is not started before
wall0 + k dt / warp. Warp 0 runs as fast as the apps allow.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .lifecycle import DONE_TOPIC, ORDER, Schedule, more_severe
from .messages import Ack, Message


@dataclass
class StepBarrier:
    """Acknowledgements of one step."""

    step: int
    expected: list[str]
    done_labels: dict[str, int]
    received: set[str] = field(default_factory=set)
    end: str | None = None
    reason: str = ""

    @classmethod
    def for_step(cls, schedule: Schedule, step: int) -> StepBarrier:
        runners = schedule.runners(step)
        return cls(step, runners, {role: schedule.done_label(role, step) for role in runners})

    def record_output(self, leaf: str, message: Message) -> None:
        """A lock-stepped output: the producer's acknowledgement if it is its done topic for this
        step. Other outputs (the sim's initial state, held values) are not acknowledgements."""
        role = message.source
        if DONE_TOPIC.get(role) == leaf and self.done_labels.get(role) == message.step:
            self.received.add(role)

    def record(self, ack: Ack) -> str | None:
        """Take an acknowledgement; return an error text for one that does not belong here."""
        if ack.step != self.step:
            return f"ack from {ack.source} for step {ack.step} while the clock is at step {self.step}"
        if ack.source not in self.expected:
            return f"ack from {ack.source!r}, which does not run at step {self.step}"
        if ack.source in self.received:
            return f"duplicate ack from {ack.source} for step {self.step}"
        self.received.add(ack.source)
        if more_severe(ack.end, self.end) != self.end:
            self.end, self.reason = ack.end, ack.reason
        return None

    @property
    def missing(self) -> list[str]:
        return [role for role in self.expected if role not in self.received]

    def stall_reason(self, timeout: float) -> str:
        missing = self.missing
        culprit = next(role for role in ORDER if role in missing)
        others = [role for role in missing if role != culprit]
        waiting = f" ({', '.join(others)} waiting on it)" if others else ""
        return f"app '{culprit}' did not finish step {self.step} within {timeout:g} s{waiting}"


@dataclass
class Pacer:
    """Wall-clock deadlines for time warp; `rebase` after a pause so no catch-up burst follows."""

    dt: float
    warp: float
    wall0: float = 0.0

    def rebase(self, now: float, step: int) -> None:
        if self.warp > 0:
            self.wall0 = now - step * self.dt / self.warp

    def release_time(self, step: int) -> float:
        """Wall time at which `step` may start (0 when running as fast as possible)."""
        if self.warp <= 0:
            return 0.0
        return self.wall0 + step * self.dt / self.warp
