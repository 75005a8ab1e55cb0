"""The lock-stepped clock's protocol and bookkeeping, free of transport and of the wall clock.

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
apps owe a granted step and make no progress for `step_timeout`, the clock names the first app
in loop order that has not finished the step; the apps later in the loop wait on it. Only time in
which a step is owed counts: not a pause, nor the wait for a paced step's release time.

`ClockCore` holds every decision; the caller passes the monotonic time, so the bookkeeping is
tested without processes (docs/design.md, "The lock-step protocol").
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from nearsub.common.runtime import keys
from nearsub.common.runtime.lifecycle import (
    DONE_TOPIC,
    NEXT_STEP_TOPICS,
    EndRequest,
    Ends,
    Fleet,
    Observer,
    Schedule,
    control_reply,
    time_limit_end,
)
from nearsub.common.runtime.messages import Ack, Control, ControlReply, Event, Message, MissionEnd, Tick


@dataclass
class Progress:
    """Which apps have finished which steps; `completed` is the last step every app (of every
    vehicle) finished. A step beyond `granted` cannot have been run: claims of it are ignored, so
    the bookkeeping stays bounded whatever is published. Apps are named by `keys.app_name`; the
    `vehicle` arguments say whose output or ack it is (None without [[vehicles]])."""

    fleet: Fleet
    completed: int = -1
    granted: int = -1
    done: dict[int, set[str]] = field(default_factory=dict)
    ends: Ends = None

    def __post_init__(self) -> None:
        self.ends = Ends(self.fleet)

    @property
    def end(self) -> EndRequest | None:
        return self.ends.end

    @property
    def schedule(self) -> Schedule:
        """The schedule of a mission of one vehicle."""
        if self.fleet.shared:
            raise ValueError("a fleet has one schedule per vehicle: see `fleet`")
        return next(iter(self.fleet.schedules.values()))

    def record_output(self, leaf: str, role: str, label: int, vehicle: str | None = None) -> None:
        """A lock-stepped output (its topic leaf, source and step label) counts when it is its
        producer's done topic."""
        if DONE_TOPIC.get(role) != leaf or vehicle not in self.fleet.schedules:
            return
        app = keys.app_name(vehicle, role)
        step = label - (self.fleet.period(app) if leaf in NEXT_STEP_TOPICS else 0)
        if step >= 0:
            self._mark(app, step)

    def record_ack(self, ack: Ack, vehicle: str | None = None) -> None:
        if vehicle not in self.fleet.schedules or ack.source not in DONE_TOPIC:
            return
        self._mark(keys.app_name(vehicle, ack.source), ack.step)
        if ack.end is not None:
            self.ends.request(vehicle, EndRequest(ack.step, ack.end, ack.reason))

    def _mark(self, app: str, step: int) -> None:
        if self.completed < step <= self.granted:
            self.done.setdefault(step, set()).add(app)
        while set(self.fleet.runners(self.completed + 1)) <= self.done.get(self.completed + 1, set()):
            self.done.pop(self.completed + 1, None)
            self.completed += 1

    def missing(self, step: int) -> list[str]:
        return [app for app in self.fleet.runners(step) if app not in self.done.get(step, set())]

    def stall_reason(self, timeout: float) -> str:
        step = self.completed + 1
        missing = self.missing(step)
        culprit = self.fleet.first_in_loop(missing)
        others = [app for app in missing if app != culprit]
        waiting = f" ({', '.join(others)} waiting on it)" if others else ""
        return f"app '{culprit}' did not finish step {step} within {timeout:g} s{waiting}"


# At a warp the clock releases the due steps in batches of at most TICK_INTERVAL wall seconds (at
# warp 50 and dt 0.05 s, ten steps a tick instead of one), and the paced schedule is never more
# than MAX_LAG wall seconds ahead of the apps: a mission that fell behind runs at its top speed
# and, once it keeps up again, does not sprint for longer than that.
TICK_INTERVAL = 0.01
MAX_LAG = 1.0
# The highest warp a mission or `nearsub clock ... warp` may ask for (a nearsub choice): far above
# what any machine achieves, and low enough that the pacing arithmetic stays finite.
MAX_WARP = 1e6


@dataclass
class GrantPolicy:
    """How far the clock lets the apps run: `window` steps ahead of the completed step at warp 0;
    with warp > 0 no further than the simulated time that has come (step k at wall0 + k dt / warp);
    never past the time limit, an end request or a pause. The grant grows in batches (fewer
    ticks), unless it reaches one of those hard caps."""

    dt: float
    warp: float
    max_steps: int
    window: int = 20
    wall0: float = 0.0

    def rebase(self, now: float, step: int) -> None:
        """Restart the warp's wall clock so that `step` is due now (after a pause)."""
        if self.warp > 0:
            self.wall0 = now - step * self.dt / self.warp

    @property
    def batch(self) -> int:
        """The fewest new steps worth a tick: half a window, at a warp the steps due in
        TICK_INTERVAL if fewer (at least one)."""
        half = max(1, self.window // 2)
        if self.warp <= 0:
            return half
        return max(1, min(half, math.floor(TICK_INTERVAL * self.warp / self.dt)))

    def hard_cap(self, pause_before: int | None, end: EndRequest | None) -> int:
        cap = self.max_steps - 1
        if pause_before is not None:
            cap = min(cap, pause_before - 1)
        if end is not None:
            cap = min(cap, end.step)
        return cap

    def limit(self, completed: int, now: float, pause_before: int | None, end: EndRequest | None) -> int:
        """The furthest step the apps may run now. At a warp this first lets the schedule slip
        so that the next step to complete is at most MAX_LAG late."""
        grant = min(completed + self.window, self.hard_cap(pause_before, end))
        if self.warp > 0:
            late = now - self.wall0 - (completed + 1) * self.dt / self.warp
            if late > MAX_LAG:
                self.wall0 += late - MAX_LAG
            grant = min(grant, math.floor((now - self.wall0) * self.warp / self.dt + 1e-9))
        return grant

    def extend(
        self, completed: int, granted: int, now: float, pause_before: int | None, end: EndRequest | None
    ) -> int | None:
        """The new grant, or None while it would grow by less than a batch short of a hard cap."""
        limit = self.limit(completed, now, pause_before, end)
        if limit > granted and (limit - granted >= self.batch or limit == self.hard_cap(pause_before, end)):
            return limit
        return None

    def release(self, completed: int, granted: int, pause_before: int | None, end: EndRequest | None) -> float | None:
        """The wall time at which the warp lets `extend` grant more, or None when the warp is not
        what holds the grant (warp 0, the window, a hard cap: then only progress or a request
        can move it, and the clock has nothing to wake up for)."""
        if self.warp <= 0:
            return None
        target = min(granted + self.batch, self.hard_cap(pause_before, end))
        if target <= granted or target > completed + self.window:
            return None
        return self.wall0 + target * self.dt / self.warp


# How long the clock may leave its mail unread (each message would otherwise wake it, a wake-up a
# message, about 2 a step): while the apps hold at least half a window of granted steps (10 steps,
# 12 ms at 800 steps/s), NAP; while the warp holds the next grant, until its release, at most
# PACED_NAP (status requests are answered within it).
NAP = 0.003
PACED_NAP = 0.05

# A control reply and the requester it goes to.
Reply = tuple[str, ControlReply]

# The achieved warp is measured over the last WARP_SPAN wall seconds, sampled every WARP_SAMPLE.
WARP_SPAN = 3.0
WARP_SAMPLE = 0.25


@dataclass
class WarpMeter:
    """Simulated seconds per wall second over the last `WARP_SPAN` seconds of the run."""

    dt: float
    samples: deque = field(default_factory=lambda: deque(maxlen=round(WARP_SPAN / WARP_SAMPLE) + 1))

    def record(self, now: float, completed: int) -> None:
        if not self.samples or now - self.samples[-1][0] >= WARP_SAMPLE:
            self.samples.append((now, completed))

    def achieved(self, now: float, completed: int) -> float | None:
        """None until the first sample is WARP_SAMPLE old (a status line's first figure is not a
        0 measured over no time)."""
        if not self.samples or now - self.samples[0][0] < WARP_SAMPLE:
            return None
        then, before = self.samples[0]
        return (completed - before) * self.dt / (now - then)


@dataclass
class Advance:
    """What the clock does now: publish a tick granting up to `tick`, send `replies`, or end
    the mission with `end` (then nothing else)."""

    tick: Tick | None = None
    replies: list[Reply] = field(default_factory=list)
    end: MissionEnd | None = None
    events: list[Event] = field(default_factory=list)  # found between the vehicles (`observer`)


class ClockCore:
    """The clock's state: progress, grants, pause and stall timer. `on_control` answers control
    requests (status, pause, resume); `advance` is called after each batch of mail.

    `warp` sets the pacing at run time (0: as fast as the apps go), rebased on the current step
    so that the simulated time does not jump; `status` reports the requested and the achieved warp.

    A pause takes effect at a step boundary: with pause before step P (the mission's
    `pause_at_step`, or a request's `at`, by default the step after the grant) the clock grants up
    to P - 1, is paused once the apps have completed P - 1, and then answers the pause requests
    that are due. `resume` grants again, the warp's wall clock restarting at the paused step.
    """

    def __init__(
        self,
        schedule: Schedule | Fleet,
        dt: float,
        warp: float,
        max_steps: int,
        step_timeout: float,
        pause_at_step: int | None = None,
        observer: Observer | None = None,
    ):
        fleet = schedule if isinstance(schedule, Fleet) else Fleet.single(schedule)
        self.progress = Progress(fleet)
        self.policy = GrantPolicy(dt, warp, max_steps, fleet.window)
        # A fleet's checks between vehicles run on each vehicle's x_{k+1} once step k is complete.
        self.observer = observer if fleet.shared else None
        self.states: dict[int, dict[str, Message]] = {}  # the sim's step -> vehicle -> state
        self.latest: dict[str, Message] = {}
        self.observed = -1
        self.dt = dt
        self.max_steps = max_steps
        self.step_timeout = step_timeout
        self.granted = -1
        self.pause_before = pause_at_step
        self.pause_requests: list[tuple[int, Control]] = []  # (pause before step, request)
        self.paused = False
        self.owed_since: float | None = None  # when the apps last progressed on a granted step
        self.owed_completed = -1
        self.meter = WarpMeter(dt)

    @property
    def step(self) -> int:
        """The next step to complete."""
        return self.progress.completed + 1

    def start(self, now: float) -> None:
        """The apps are up: step 0 is due now."""
        self.policy.rebase(now, 0)

    def on_control(self, request: Control, now: float) -> list[Reply]:
        """The immediate answers to a control request (a pause is answered when it is reached)."""
        if request.cmd == "status":
            return [self.reply(request, data=self.status(now))]
        if request.cmd == "warp":
            warp = request.args.get("warp")
            if not isinstance(warp, (int, float)) or isinstance(warp, bool) or not 0 <= warp <= MAX_WARP:
                error = f"warp: must be a number from 0 to {MAX_WARP:g}, got {warp!r}"
                return [self.reply(request, ok=False, error=error)]
            self.policy.warp = float(warp)
            self.policy.rebase(now, self.step)
            return [self.reply(request, data=self.status(now))]
        if request.cmd == "pause":
            at = request.args.get("at", self.granted + 1)
            if not isinstance(at, int) or isinstance(at, bool):
                return [self.reply(request, ok=False, error=f"pause: 'at' must be a step number, got {at!r}")]
            if at <= self.granted:
                error = f"step {at} has passed or is granted (granted up to {self.granted})"
                return [self.reply(request, ok=False, error=error)]
            self.pause_before = at if self.pause_before is None else min(self.pause_before, at)
            self.pause_requests.append((at, request))
            return []
        if request.cmd == "resume":
            self.paused = False
            self.pause_before = None
            self.policy.rebase(now, self.step)
            return [self.reply(request, data={"step": self.step})]
        return [self.reply(request, ok=False, error=f"clock: unknown command {request.cmd!r}")]

    def status(self, now: float) -> dict:
        """The next step to complete, its simulated time, whether paused, and the warp requested
        and achieved (None before the first measurement)."""
        achieved = self.meter.achieved(now, self.progress.completed)
        return {
            "step": self.step,
            "t": self.step * self.dt,
            "paused": self.paused,
            "warp": self.policy.warp,
            "achieved_warp": achieved,
        }

    def reply(self, request: Control, **answer) -> Reply:
        return request.reply_to, control_reply(request, "clock", self.step, self.dt, **answer)

    def record_state(self, vehicle: str, label: int, state: Message) -> None:
        """A vehicle's state, for the observer, by the step whose sim produced it."""
        step = label - self.progress.fleet.period(keys.app_name(vehicle, "sim"))
        if self.observer is not None and self.observed < step <= self.granted:
            self.states.setdefault(step, {})[vehicle] = state

    def observe(self) -> list[Event]:
        """Run the observer on each newly completed step, with each vehicle's latest state as
        `run_inprocess` has it: its events, and its end request."""
        found = []
        while self.observer is not None and self.observed < self.progress.completed:
            self.observed += 1
            self.latest.update(self.states.pop(self.observed, {}))
            result = self.observer.observe(self.observed, self.latest)
            found += result.events
            if result.end is not None:
                self.progress.ends.request(None, EndRequest(self.observed, result.end, result.reason))
        return found

    def advance(self, now: float) -> Advance:
        events = self.observe()
        completed, end = self.progress.completed, self.progress.end
        self.meter.record(now, completed)
        if end is None and completed >= self.max_steps - 1:
            end = time_limit_end(self.max_steps, self.dt)
        # An error ends the mission at once: the step it broke may never complete (an app that
        # failed at start-up leaves its consumers waiting on step 0).
        if end is not None and (completed >= end.step or end.outcome == "error"):
            return Advance(end=self.mission_end(end.step + 1, end.outcome, end.reason), events=events)
        advance = Advance(events=events)
        if self.pause_before is not None and completed == self.pause_before - 1:
            self.paused = True
        if self.paused:  # answer the requests due now, also those that came after the pause began
            step = self.step
            advance.replies = [self.reply(r, data={"step": step}) for at, r in self.pause_requests if at <= step]
            self.pause_requests = [(at, r) for at, r in self.pause_requests if at > step]
        else:
            advance.tick = self.grant(completed, now)
        if self.stalled(completed, now):
            reason = self.progress.stall_reason(self.step_timeout)
            return Advance(
                replies=advance.replies, end=self.mission_end(completed + 1, "stalled", reason), events=events
            )
        return advance

    def wake_in(self, now: float) -> float:
        """Wall seconds until the clock must act with no mail arriving: the release of the next
        paced batch, the stall deadline, or the warp meter's next sample, whichever is first.
        A paced step that is due but held by the window waits for progress: waking for it would
        spin (the cause of warp 50 running slower than warp 25 on a machine that cannot hold it)."""
        wait = WARP_SAMPLE
        release = None
        if not self.paused:
            completed = self.progress.completed
            release = self.policy.release(completed, self.granted, self.pause_before, self.progress.end)
        if release is not None:
            wait = min(wait, release - now)
        if self.owed_since is not None:
            wait = min(wait, self.owed_since + self.step_timeout - now)
        return max(wait, 0.0)

    def nap(self, now: float) -> float:
        """Wall seconds the clock may sleep without reading its mail, no more than `wake_in`: 0
        when progress may be due a grant at once (a fleet's one-step window), when paused (a
        resume is answered at once) or when a hard cap holds the grant (the end is near)."""
        if self.paused:
            return 0.0
        policy, completed = self.policy, self.progress.completed
        if policy.release(completed, self.granted, self.pause_before, self.progress.end) is not None:
            return min(self.wake_in(now), PACED_NAP)
        lead = self.granted - completed
        if lead >= policy.window // 2 > 0 and self.granted < policy.hard_cap(self.pause_before, self.progress.end):
            return min(self.wake_in(now), NAP)
        return 0.0

    def grant(self, completed: int, now: float) -> Tick | None:
        limit = self.policy.extend(completed, self.granted, now, self.pause_before, self.progress.end)
        if limit is None:
            return None
        self.granted = self.progress.granted = limit
        return Tick(step=limit, t=limit * self.dt, source="clock")

    def stalled(self, completed: int, now: float) -> bool:
        """True once a granted step has been owed for `step_timeout` without progress. The timer
        runs only while a step is owed, so a pause or a paced wait does not count."""
        if self.granted <= completed:
            self.owed_since = None
        elif self.owed_since is None or completed != self.owed_completed:
            self.owed_since = now
        self.owed_completed = completed
        return self.owed_since is not None and now - self.owed_since > self.step_timeout

    def mission_end(self, step: int, outcome: str, reason: str) -> MissionEnd:
        return MissionEnd(step=step, t=step * self.dt, source="clock", outcome=outcome, reason=reason)
