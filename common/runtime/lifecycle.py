"""One app lifecycle, in the MOOS-IvP manner, and the lock-step schedule that drives it.

Every lock-stepped app is a `Core` with three phases:
- `startup()`: called once; returns the messages to publish at the first step (the sim's x_0);
- `new_mail(mail)`: the inputs that are new since the last run, one per topic;
- `iterate(step, t)`: compute and return this step's outputs, events and an optional end request.

Transport is not the core's business: the process shell (`apps/shell.py`) feeds a core from Zenoh,
and `run_inprocess` feeds the same cores from a dict. Both follow `Schedule`, so they produce the
same messages in the same order (SPEC section 4).

The schedule: within one step the order is helm, pid, sim (the thesis loop). An app with period p
runs at steps that are multiples of p. Every output carries the step it is valid at; a consumer at
step k waits for the latest label a producer publishes at or before k, which is
floor(k / p_producer) * p_producer. The sim's state output is labelled with the step it describes
(x_{k+1} after integrating step k), so the helm at step k reads x_k.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

from nearsub.common.runtime.messages import Event, Message

ORDER = ("helm", "pid", "sim")

# Which role publishes each lock-stepped topic.
PRODUCER = {"desired": "helm", "input": "pid", "state": "sim"}

# The output that tells the clock an app has finished a step: its acknowledgement. An app sends
# an explicit Ack only when it asks to end the mission or did not publish this output (e.g. the
# sim on divergence); that halves the messages per step (see common/clock.py).
DONE_TOPIC = {"helm": "desired", "pid": "input", "sim": "state"}

# Topics labelled with the step they lead to (the sim's x_{k+1} after step k).
NEXT_STEP_TOPICS = frozenset({"state"})

# Outcomes a core may request, from most to least severe; the clock keeps the most severe.
OUTCOME_SEVERITY = ("diverged", "collision", "error", "completed", "time_limit")


@dataclass
class Iteration:
    """What one `iterate` call produced. Outputs are (topic leaf, message) in publish order."""

    outputs: list[tuple[str, Message]] = field(default_factory=list)
    events: list[Event] = field(default_factory=list)
    end: str | None = None
    reason: str = ""


class Core(Protocol):
    role: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]

    def startup(self) -> list[tuple[str, Message]]: ...

    def new_mail(self, mail: dict[str, Message]) -> None: ...

    def iterate(self, step: int, t: float) -> Iteration: ...

    def progress(self) -> dict: ...

    def restore(self, progress: dict) -> None: ...


@dataclass(frozen=True)
class Schedule:
    periods: dict[str, int]

    def runs(self, role: str, step: int) -> bool:
        return step % self.periods[role] == 0

    def runners(self, step: int) -> list[str]:
        return [role for role in ORDER if self.runs(role, step)]

    def expected_label(self, topic: str, step: int) -> int:
        period = self.periods[PRODUCER[topic]]
        return (step // period) * period


def more_severe(a: str | None, b: str | None) -> str | None:
    """The more severe of two end requests (None means no request)."""
    if a is None:
        return b
    if b is None:
        return a
    rank = {name: i for i, name in enumerate(OUTCOME_SEVERITY)}
    return a if rank.get(a, 0) <= rank.get(b, 0) else b


class Inbox:
    """The latest accepted message per input topic of one app, and what its core has seen.

    `offer` accepts a message only from the topic's producer and only with a label newer than
    the one held; anything else is returned as an error text (never raised), so a receiver can
    report it and carry on.
    """

    def __init__(self, inputs: tuple[str, ...], schedule: Schedule):
        self.inputs = inputs
        self.schedule = schedule
        self.held: dict[str, Message] = {}
        self.delivered: dict[str, int] = {}

    def offer(self, leaf: str, message: Message) -> str | None:
        producer = PRODUCER[leaf]
        if message.source != producer:
            return f"{leaf} from source {message.source!r} ignored: only {producer!r} publishes {leaf}"
        held = self.held.get(leaf)
        if held is not None and message.step <= held.step:
            return f"{leaf} with step {message.step} ignored: already holding step {held.step}"
        self.held[leaf] = message
        return None

    def waiting_for(self, step: int) -> list[str]:
        """Input topics whose expected label for `step` has not arrived yet."""
        missing = []
        for leaf in self.inputs:
            held = self.held.get(leaf)
            if held is None or held.step < self.schedule.expected_label(leaf, step):
                missing.append(leaf)
        return missing

    def take(self, step: int) -> dict[str, Message]:
        """The mail for `step`: inputs whose label is new to the core. Call when nothing is missing."""
        mail = {}
        for leaf in self.inputs:
            message = self.held[leaf]
            expected = self.schedule.expected_label(leaf, step)
            if message.step != expected:
                raise RuntimeError(f"step {step}: {leaf} has label {message.step}, expected {expected}")
            if self.delivered.get(leaf) != message.step:
                mail[leaf] = message
                self.delivered[leaf] = message.step
        return mail


@dataclass
class InProcessResult:
    outcome: str
    reason: str
    steps: int
    messages: list[tuple[str, str, Message]]  # (role, topic leaf or "events", message)

    def topic(self, leaf: str) -> list[Message]:
        return [m for _, t, m in self.messages if t == leaf]


def run_inprocess(
    cores: dict[str, Core],
    schedule: Schedule,
    dt: float,
    max_steps: int,
    swaps: dict[int, dict[str, Core]] | None = None,
) -> InProcessResult:
    """Run the lock-stepped cores in one process, exactly as the clock and shells would.

    `swaps` maps a step to replacement cores ({role: core}), swapped in before that step as
    `nearsub swap --at-step` does: the new core takes over the old one's progress and inbox.
    """
    cores = dict(cores)
    swaps = swaps or {}
    inboxes = {role: Inbox(cores[role].inputs, schedule) for role in ORDER}
    messages: list[tuple[str, str, Message]] = []

    def publish(role: str, leaf: str, message: Message) -> None:
        messages.append((role, leaf, message))
        for inbox in inboxes.values():
            if leaf in inbox.inputs:
                error = inbox.offer(leaf, message)
                if error:
                    raise RuntimeError(error)

    for role in ORDER:
        for leaf, message in cores[role].startup():
            publish(role, leaf, message)

    outcome, reason = None, ""
    step = 0
    while step < max_steps:
        t = step * dt
        for role, replacement in swaps.get(step, {}).items():
            replacement.restore(cores[role].progress())
            cores[role] = replacement
        for role in schedule.runners(step):
            missing = inboxes[role].waiting_for(step)
            if missing:
                raise RuntimeError(f"{role} at step {step} is missing {missing}")
            core = cores[role]
            core.new_mail(inboxes[role].take(step))
            result = core.iterate(step, t)
            for leaf, message in result.outputs:
                publish(role, leaf, message)
            for event in result.events:
                messages.append((role, "events", event))
            if more_severe(result.end, outcome) != outcome:
                outcome, reason = result.end, result.reason
        step += 1
        if outcome is not None:
            break
    if outcome is None:
        outcome, reason = "time_limit", f"reached the time limit of {max_steps * dt:g} s"
    return InProcessResult(outcome, reason, step, messages)
