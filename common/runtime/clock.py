"""The lock-stepped clock's protocol, free of transport (SPEC section 4).

The clock grants steps; the apps run them. A tick carrying step G means "you may run every step
up to and including G". Within the grant the apps are driven by their data: the helm runs step k
when x_k has arrived, the pid when x_k and the helm's x_d have, the sim when the pid's u_k has,
each exactly once, in the thesis order. So the outcome does not depend on when a grant arrives,
and the clock is off the critical path: it grants a window of steps ahead of the slowest app
(warp 0), or the steps whose simulated time has come (warp > 0), and stops granting to pause.

The clock follows progress through the apps' done outputs (lifecycle.DONE_TOPIC: the helm's
desired state, the pid's input, the sim's next state), or an explicit Ack when an app asks to end
the mission. An end requested at step k stops every app after step k: the request is published
before the outputs of step k, so every app learns of it before it could start step k + 1. If the
progress stalls for `step_timeout`, the clock names the first app in loop order that has not
finished the step; the apps later in the loop wait on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from nearsub.common.runtime.lifecycle import DONE_TOPIC, NEXT_STEP_TOPICS, ORDER, EndRequest, Schedule, first_end
from nearsub.common.runtime.messages import Ack, Message


@dataclass
class Progress:
    """Which apps have finished which steps; `completed` is the last step every app finished."""

    schedule: Schedule
    completed: int = -1
    done: dict[int, set[str]] = field(default_factory=dict)
    end: EndRequest | None = None

    def record_output(self, leaf: str, message: Message) -> None:
        """A lock-stepped output counts when it is its producer's done topic."""
        role = message.source
        if DONE_TOPIC.get(role) != leaf:
            return
        step = message.step - (self.schedule.periods[role] if leaf in NEXT_STEP_TOPICS else 0)
        if step >= 0:
            self._mark(role, step)

    def record_ack(self, ack: Ack) -> None:
        self._mark(ack.source, ack.step)
        if ack.end is not None:
            self.end = first_end(self.end, EndRequest(ack.step, ack.end, ack.reason))

    def _mark(self, role: str, step: int) -> None:
        if step > self.completed:
            self.done.setdefault(step, set()).add(role)
        while set(self.schedule.runners(self.completed + 1)) <= self.done.get(self.completed + 1, set()):
            self.done.pop(self.completed + 1, None)
            self.completed += 1

    def missing(self, step: int) -> list[str]:
        return [role for role in self.schedule.runners(step) if role not in self.done.get(step, set())]

    def stall_reason(self, timeout: float) -> str:
        step = self.completed + 1
        missing = self.missing(step)
        culprit = next(role for role in ORDER if role in missing)
        others = [role for role in missing if role != culprit]
        waiting = f" ({', '.join(others)} waiting on it)" if others else ""
        return f"app '{culprit}' did not finish step {step} within {timeout:g} s{waiting}"


@dataclass
class GrantPolicy:
    """How far the clock lets the apps run: `window` steps ahead of the completed step at warp 0;
    with warp > 0 no further than the simulated time that has come (step k at wall0 + k dt / warp);
    never past the time limit, an end request or a pause."""

    dt: float
    warp: float
    max_steps: int
    window: int = 20
    wall0: float = 0.0

    def rebase(self, now: float, step: int) -> None:
        """Restart the warp's wall clock so that `step` is due now (after a pause)."""
        if self.warp > 0:
            self.wall0 = now - step * self.dt / self.warp

    def limit(self, completed: int, now: float, pause_before: int | None, end: EndRequest | None) -> int:
        grant = min(completed + self.window, self.max_steps - 1)
        if self.warp > 0:
            grant = min(grant, math.floor((now - self.wall0) * self.warp / self.dt + 1e-9))
        if pause_before is not None:
            grant = min(grant, pause_before - 1)
        if end is not None:
            grant = min(grant, end.step)
        return grant
