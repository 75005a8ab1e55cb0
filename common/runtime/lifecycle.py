"""One app lifecycle, in the MOOS-IvP manner, and the lock-step rules that drive it.

Every lock-stepped app is a `Core` with three phases:
- `startup()`: called once; returns the messages to publish at the first step (the sim's x_0);
- `new_mail(mail)`: the inputs that are new since the last run, one per topic;
- `iterate(step, t)`: compute and return this step's outputs, events and an optional end request.

Transport is not the core's business. A `Stepper` runs one core under the lock-step rules; the
process shell (`apps/shell.py`) feeds it from Zenoh, and `run_inprocess` feeds one stepper per
core from the others, so both produce the same messages in the same order (docs/design.md,
"The lock-step protocol").

The schedule: within one step the order is helm, pid, sim (the thesis loop). An app with period p
runs at steps that are multiples of p. Every output carries the step it is valid at; a consumer at
step k waits for the latest label a producer publishes at or before k, which is
floor(k / p_producer) * p_producer. The sim's state output is labelled with the step it describes
(x_{k+1} after integrating step k), so the helm at step k reads x_k.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Protocol

import msgpack

from nearsub.common.runtime import keys
from nearsub.common.runtime.fields import for_people
from nearsub.common.runtime.messages import (
    VEHICLE_TOPICS,
    Ack,
    Control,
    ControlReply,
    Event,
    Message,
    Poke,
    decode,
    encode,
)

ORDER = ("helm", "pid", "sim")

# Which role publishes each lock-stepped topic (the sim's forces at x_k go out after x_k, for the
# helm's N_uv compensation).
PRODUCER = {"desired": "helm", "input": "pid", "state": "sim", "forces": "sim"}
# The roles that may read each of them (a core declares which it does read: its `inputs`).
CONSUMERS = {"desired": ("pid",), "input": ("sim",), "state": ("helm", "pid"), "forces": ("helm",)}

# The output that tells the clock an app has finished a step: its acknowledgement. An app sends
# an explicit Ack only when it asks to end the mission or did not publish this output (e.g. the
# sim on divergence); that halves the messages per step (see runtime/clock.py).
DONE_TOPIC = {"helm": "desired", "pid": "input", "sim": "state"}

# The source name of a person steering a running mission (`nearsub tap pub`), and the topics an
# operator may override: the helm's desired state (at the pid) and the pid's input (at the sim).
OPERATOR = "operator"
OPERATOR_TOPICS = ("desired", "input", "poke")
# Topics only an operator publishes, and the role that consumes them: the helm's mission variables
# (`nearsub poke`). Each poke is delivered once, at the first step it is due; pokes due at the same
# step are merged in the order they came (the later value of a variable wins).
OPERATOR_ONLY = {"poke": "helm"}

# Topics labelled with the step they lead to (the sim's x_{k+1} after step k, and its forces there).
NEXT_STEP_TOPICS = frozenset({"state", "forces"})

# Outcomes a core may request, from most to least severe; the clock keeps the most severe.
OUTCOME_SEVERITY = ("diverged", "collision", "error", "completed", "time_limit")


@dataclass
class Iteration:
    """What one `iterate` call produced. Outputs are (topic leaf, message) in publish order.

    `then`, if set, is more work of the same step that nobody waits for before these outputs: it
    runs once they are published, and what it returns is published after them (the sim's forces
    at x_{k+1}: the pid computes u_{k+1} from x_{k+1} while the surrogate server answers)."""

    outputs: list[tuple[str, Message]] = field(default_factory=list)
    events: list[Event] = field(default_factory=list)
    end: str | None = None
    reason: str = ""
    then: Callable[[], Iteration] | None = None


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

    def stride(self, topic: str, consumer: str) -> int:
        """The spacing of the labels of `topic` that `consumer` receives. A consumer whose period
        is a longer multiple of the producer's reads only the outputs labelled with its own steps,
        so it receives only those (on the topic's feed, `keys.feed`) and wakes only for them: the
        helm of period 5 gets every 5th state and forces. Otherwise every output: the producer's
        period. Operator topics are never strided: an override reaches its consumer on the topic."""
        produced, period = self.periods[PRODUCER[topic]], self.periods[consumer]
        if topic in OPERATOR_TOPICS or period <= produced or period % produced:
            return produced
        return period

    def feeds(self, topic: str) -> tuple[int, ...]:
        """The strides longer than the producer's period at which `topic` is read: its producer
        also publishes each output whose label is a multiple of one on that stride's feed."""
        produced = self.periods[PRODUCER[topic]]
        strides = {self.stride(topic, role) for role in CONSUMERS[topic] if role in self.periods}
        return tuple(sorted(stride for stride in strides if stride > produced))

    def expected_label(self, topic: str, step: int, consumer: str) -> int:
        """The label of `topic` that `consumer` reads at `step`: the latest one it receives."""
        stride = self.stride(topic, consumer)
        return (step // stride) * stride


class Inbox:
    """The latest accepted message per input topic of one app, and what its core has seen.

    `offer` accepts a message only from the topic's producer and only with the next label in
    the producer's sequence (its period apart from the one held; the first one the label of the
    app's current step). Anything else, a stale label, a label from the far future or one off the
    producer's period, is returned as an error text (never raised), so a receiver can report it
    and carry on; the inbox holds one message per topic whatever it is offered.
    """

    def __init__(self, inputs: tuple[str, ...], schedule: Schedule, role: str):
        self.inputs = inputs
        self.schedule = schedule
        self.role = role
        self.held: dict[str, Message] = {}
        self.delivered: dict[str, int] = {}

    def offer(self, leaf: str, message: Message, step: int) -> str | None:
        """Offer an input to an app that is about to run `step`."""
        producer = PRODUCER.get(leaf, OPERATOR)
        if message.source != producer:
            return f"{leaf} from source {message.source!r} ignored: only {producer!r} publishes {leaf}"
        held = self.held.get(leaf)
        stride = self.schedule.stride(leaf, self.role)
        if held is not None:
            expected = held.step + stride
        elif self.schedule.runs(self.role, step) or stride == self.schedule.periods[producer]:
            expected = self.schedule.expected_label(leaf, step, self.role)
        else:  # a strided reader that does not run `step` receives the label of its next step first
            expected = (step // stride + 1) * stride
        if message.step != expected:
            holding = "nothing" if held is None else f"step {held.step}"
            return f"{leaf} with step {message.step} ignored: holding {holding}, the next is step {expected}"
        self.held[leaf] = message
        return None

    def waiting_for(self, step: int) -> list[str]:
        """Input topics whose expected label for `step` has not arrived yet."""
        missing = []
        for leaf in self.inputs:
            held = self.held.get(leaf)
            if held is None or held.step < self.schedule.expected_label(leaf, step, self.role):
                missing.append(leaf)
        return missing

    def take(self, step: int) -> dict[str, Message]:
        """The mail for `step`: inputs whose label is new to the core. Call when nothing is missing."""
        mail = {}
        for leaf in self.inputs:
            message = self.held[leaf]
            expected = self.schedule.expected_label(leaf, step, self.role)
            if message.step != expected:
                raise RuntimeError(f"step {step}: {leaf} has label {message.step}, expected {expected}")
            if self.delivered.get(leaf) != message.step:
                mail[leaf] = message
                self.delivered[leaf] = message.step
        return mail


@dataclass(frozen=True)
class Fleet:
    """Every lock-stepped app of a mission: each vehicle's helm, pid and sim under its vehicle's
    schedule. A mission without [[vehicles]] is one vehicle named None, whose apps are named by
    role alone (keys.app_name).

    Several vehicles share one lock-step: the clock grants step k + 1 only once every vehicle's
    apps have finished step k (`window` 1), so an end requested by any app at step k (or found
    between the vehicles, `Observer`) stops them all after step k whatever their speed."""

    schedules: dict[str | None, Schedule]

    @classmethod
    def single(cls, schedule: Schedule) -> Fleet:
        return cls({None: schedule})

    @property
    def vehicles(self) -> list[str | None]:
        return list(self.schedules)

    @property
    def shared(self) -> bool:
        """Several vehicles: one step at a time, ends decided by the clock (`Ends`)."""
        return len(self.schedules) > 1

    @property
    def window(self) -> int:
        """Steps the clock grants ahead of the last completed one (docs/design.md, "Grants")."""
        return 1 if self.shared else 20

    def runners(self, step: int) -> list[str]:
        """The apps that run `step`, in loop order: helm, pid, sim of each vehicle in turn."""
        return [keys.app_name(v, role) for v, schedule in self.schedules.items() for role in schedule.runners(step)]

    def period(self, app: str) -> int:
        vehicle, role = keys.split_app(app)
        return self.schedules[vehicle].periods[role]

    def first_in_loop(self, apps: list[str]) -> str:
        """The app the others wait on: the earliest role in loop order, then vehicle order."""
        order = {v: i for i, v in enumerate(self.schedules)}
        return min(apps, key=lambda app: (ORDER.index(keys.split_app(app)[1]), order[keys.split_app(app)[0]]))


class Observer(Protocol):
    """Checks between vehicles (common/physics/encounters.py): after every vehicle finished step
    k, `observe(k, states)` sees each vehicle's x_{k+1} and returns events and an optional end."""

    def observe(self, step: int, states: dict[str, Message]) -> Iteration: ...


@dataclass(frozen=True)
class EndRequest:
    """An app's request to end the mission after step `step` with `outcome`."""

    step: int
    outcome: str
    reason: str = ""


def first_end(held: EndRequest | None, request: EndRequest) -> EndRequest:
    """The end request that wins: the earliest step, then the most severe outcome."""
    if held is None or request.step < held.step:
        return request
    rank = {name: i for i, name in enumerate(OUTCOME_SEVERITY)}
    if request.step == held.step and rank.get(request.outcome, 0) < rank.get(held.outcome, 0):
        return request
    return held


class Ends:
    """The end of the mission from the end requests of its apps. One vehicle: the first request
    wins (`first_end`). A fleet: a failure (diverged, collision, error) ends it at once; a
    vehicle's "completed" only marks that vehicle done (it carries on, all-stop, as pHelmIvP
    does), and the mission completes at the step the last vehicle completes."""

    def __init__(self, fleet: Fleet):
        self.fleet = fleet
        self.failure: EndRequest | None = None
        self.completed: dict[str | None, EndRequest] = {}

    def request(self, vehicle: str | None, request: EndRequest) -> None:
        if not self.fleet.shared or request.outcome != "completed":
            self.failure = first_end(self.failure, request)
        elif vehicle not in self.completed:
            self.completed[vehicle] = request

    @property
    def end(self) -> EndRequest | None:
        if len(self.completed) < len(self.fleet.vehicles):
            return self.failure
        last = max(self.completed.values(), key=lambda r: r.step)
        names = ", ".join(str(v) for v in self.completed)
        completed = EndRequest(last.step, "completed", f"every vehicle completed ({names}); last: {last.reason}")
        return first_end(self.failure, completed)


def time_limit_end(max_steps: int, dt: float) -> EndRequest:
    """The end every mission reaches when no app asks earlier: after its last step."""
    return EndRequest(max_steps - 1, "time_limit", f"reached the time limit of {max_steps * dt:g} s")


def control_reply(
    request: Control, source: str, step: int, dt: float, ok: bool = True, data: dict | None = None, error: str = ""
) -> ControlReply:
    """The answer to a control request, sent by `source` at `step`."""
    return ControlReply(
        step=step, t=step * dt, source=source, request_id=request.request_id, ok=ok, data=data or {}, error=error
    )


# Channels a stepper publishes on besides its core's output topics.
ACK = "ack"
EVENTS = "events"


class Stepper:
    """Runs one core under the lock-step rules, free of transport: the process shell and
    `run_inprocess` feed it inputs, grants and end requests, and publish what `run` returns.

    The rules: step k runs once it is granted, not past an end request, and its inputs have
    arrived; a slower app (period p) runs only at multiples of p and its consumers hold its
    latest output. The start-up outputs go out with the first granted step. An end request goes
    out on `ACK` before the outputs of its step, so every app hears of it before it could run
    the next one; so does an explicit Ack when the core did not publish its done topic.
    Exceptions of the `recoverable` types from `startup` or `iterate` (a service that stopped answering) end
    the mission with "error" and an error event instead of crashing the app. In a fleet
    (`ends_itself` False) an app's own end request does not stop it: the clock decides the end
    (`Ends`) and never grants past it. With a `window` (the clock's, `Fleet.window`), a grant
    further ahead of this app than the clock ever gives is refused: the clock grants at most
    `window` steps past the last step every app has finished, which is before this app's step.
    """

    def __init__(
        self,
        core: Core,
        schedule: Schedule,
        dt: float,
        max_steps: int,
        recoverable: tuple[type[Exception], ...] = (),
        ends_itself: bool = True,
        window: int | None = None,
    ):
        self.core = core
        self.schedule = schedule
        self.dt = dt
        self.recoverable = recoverable
        self.ends_itself = ends_itself
        self.window = window
        self.inbox = Inbox(core.inputs, schedule, core.role)
        self.granted = -1
        self.stop_after = max_steps - 1
        self.started = False
        self.step = 0  # the next step this app will run
        self.overrides: dict[str, list[tuple[int, Message]]] = {}  # leaf -> [(from step, message)]

    def receives(self, leaf: str, step: int) -> bool:
        """Whether this app receives the output of `leaf` labelled `step` (`Schedule.stride`)."""
        return step % self.schedule.stride(leaf, self.core.role) == 0

    def offer(self, leaf: str, message: Message) -> str | None:
        """Accept an input (see `Inbox.offer`); an error text when it is refused."""
        return self.inbox.offer(leaf, message, self.step)

    def override(self, leaf: str, message: Message, from_step: int | None = None) -> Event:
        """An operator's value for input `leaf`, which the core receives in place of the
        producer's from `from_step` (by default the next step this app runs) to the end of the
        mission or the next override. Returns the event that records it, with its step, so the
        run can be replayed (`run_inprocess(operator=...)`)."""
        step = self.step if from_step is None else from_step
        pending = [(k, m) for k, m in self.overrides.get(leaf, []) if k < step or leaf in OPERATOR_ONLY]
        self.overrides[leaf] = [*pending, (step, message)]
        fields = message.model_dump(mode="json", exclude={"schema_version", "step", "t", "source"})
        shown = for_people(type(message).__name__, fields)  # for people: angles in degrees, named so
        detail = f"operator {leaf} from step {step}: " + ", ".join(f"{k}={v}" for k, v in shown.items())
        data = {"leaf": leaf, "step": step, "message": message.model_dump(mode="json")}
        return Event(step=step, t=step * self.dt, source=self.core.role, kind="info", detail=detail, data=data)

    def _overridden(self, step: int) -> dict[str, Message]:
        """The operator values in force at `step`; the ones they replace are forgotten (pokes:
        the ones due, once, merged)."""
        mail = {}
        for leaf, entries in self.overrides.items():
            due = [entry for entry in entries if entry[0] <= step]
            if due and leaf in OPERATOR_ONLY:
                values = {name: value for _, poke in due for name, value in poke.values.items()}
                mail[leaf] = Poke(step=step, t=step * self.dt, source=OPERATOR, values=values)
                self.overrides[leaf] = [entry for entry in entries if entry[0] > step]
            elif due:
                mail[leaf] = due[-1][1]
                self.overrides[leaf] = [due[-1], *(entry for entry in entries if entry[0] > step)]
        return mail

    def grant(self, step: int) -> str | None:
        """Let the app run up to `step`; an error text (and no grant) for a grant out of protocol."""
        if self.window is not None and step > self.step - 1 + self.window:
            return (
                f"tick to step {step} ignored: the clock grants at most {self.window} steps past the "
                f"last finished one, and this app is at step {self.step}"
            )
        self.granted = max(self.granted, step)
        return None

    def end_after(self, step: int) -> None:
        self.stop_after = min(self.stop_after, step)

    def blocked(self) -> list[str]:
        """The inputs this app waits for at a step it may run; empty when it has nothing to do."""
        if self.step > min(self.granted, self.stop_after):
            return []
        return self.inbox.waiting_for(self.step)

    def run(self) -> list[tuple[str, Message]]:
        """Run every permitted step whose inputs have arrived; (channel, message) in publish order."""
        return list(self.produce())

    def produce(self) -> Iterator[tuple[str, Message]]:
        """`run`, yielding each output as soon as it exists, so a shell that publishes while it
        iterates sends a step's outputs before the step's `then` work starts."""
        while self.step <= min(self.granted, self.stop_after):
            if not self.started:
                self.started = True
                try:
                    yield from self.core.startup()
                except self.recoverable as exc:  # e.g. the sim's first interaction query
                    yield from self._outputs(self.step, self._failure(self.step, exc))
                    self.step += 1
                    break
            if self.schedule.runs(self.core.role, self.step):
                if self.inbox.waiting_for(self.step):
                    break
                yield from self._iterate(self.step)
            self.step += 1

    def _iterate(self, step: int) -> Iterator[tuple[str, Message]]:
        t = step * self.dt
        self.core.new_mail(self.inbox.take(step) | self._overridden(step))
        try:
            result = self.core.iterate(step, t)
        except self.recoverable as exc:
            result = self._failure(step, exc)
        yield from self._outputs(step, result)
        if result.then is not None:
            try:
                later = result.then()
            except self.recoverable as exc:
                later = self._failure(step, exc)
            yield from self._outputs(step, later, done=True)

    def _failure(self, step: int, exc: Exception) -> Iteration:
        """A recoverable exception ends the mission with "error" and an error event."""
        error = Event(step=step, t=step * self.dt, source=self.core.role, kind="error", detail=str(exc))
        return Iteration(events=[error], end="error", reason=str(exc))

    def _outputs(self, step: int, result: Iteration, done: bool = False) -> list[tuple[str, Message]]:
        """The messages of `result`, with an Ack first when it asks to end or the step is not
        `done` by its done topic (`done`: a `then` result, whose step already is)."""
        role = self.core.role
        t = step * self.dt
        published: list[tuple[str, Message]] = []
        finished = done or any(leaf == DONE_TOPIC[role] for leaf, _ in result.outputs)
        if result.end is not None or not finished:
            published.append((ACK, Ack(step=step, t=t, source=role, end=result.end, reason=result.reason)))
            if result.end is not None and self.ends_itself:
                self.end_after(step)
        published.extend(result.outputs)
        published.extend((EVENTS, event) for event in result.events)
        return published

    # -- swap: hand the app over to a new instance at a step boundary --------------------------
    def handover(self, step: int) -> bytes | None:
        """What a successor needs to run from `step` (the core's progress and the inputs held),
        once this app has reached `step` with the inputs made before it; None before that. The
        inputs of `step` made within it, by an app earlier in ORDER (the pid's desired, the sim's
        input), are made only once the clock grants `step` again: the successor receives them."""
        if self.step != step:
            return None
        role = ORDER.index(self.core.role)
        if any(ORDER.index(PRODUCER[leaf]) > role for leaf in self.inbox.waiting_for(step)):
            return None
        held = {leaf: encode(message) for leaf, message in self.inbox.held.items()}
        overrides = {leaf: [(k, encode(m)) for k, m in entries] for leaf, entries in self.overrides.items()}
        state = {"progress": self.core.progress(), "held": held, "delivered": self.inbox.delivered}
        return msgpack.packb(state | {"overrides": overrides})

    def take_over(self, handover: bytes, step: int) -> None:
        """Continue from a predecessor's `handover` at `step`: no step is skipped or repeated."""
        state = msgpack.unpackb(handover)
        self.core.restore(state["progress"])
        for leaf, raw in state["held"].items():
            self.inbox.held[leaf] = decode(raw, VEHICLE_TOPICS[leaf], f"handover {leaf}")
        self.inbox.delivered = dict(state["delivered"])
        # The mail the predecessor's core had already taken (the pid's desired of the helm's last
        # step): the new core starts from it, as the old one would have gone on.
        seen = {leaf: m for leaf, m in self.inbox.held.items() if self.inbox.delivered.get(leaf) == m.step}
        if seen:
            self.core.new_mail(seen)
        for leaf, entries in state["overrides"].items():
            model = VEHICLE_TOPICS[leaf]
            self.overrides[leaf] = [(k, decode(raw, model, f"handover {leaf}")) for k, raw in entries]
        self.started = True
        self.step = step
        self.granted = step - 1


@dataclass
class InProcessResult:
    outcome: str
    reason: str
    steps: int
    messages: list[tuple[str, str, Message]]  # (app, topic leaf or "events", message)

    def topic(self, leaf: str, vehicle: str | None = None) -> list[Message]:
        """One topic of one vehicle (None: the mission without [[vehicles]], or the checks
        between vehicles)."""
        return [m for app, t, m in self.messages if t == leaf and keys.split_app(app)[0] == vehicle]


# The source of the events the checks between vehicles find (`Observer`).
ENCOUNTERS = "encounters"


def run_inprocess(
    cores: dict,
    schedule: Schedule | Fleet,
    dt: float,
    max_steps: int,
    swaps: dict[int, dict[str, Core]] | None = None,
    operator: list[tuple[str, str, int, Message]] = (),
    observer: Observer | None = None,
) -> InProcessResult:
    """Run the lock-stepped cores in one process, exactly as the clock and shells would, and
    return what they published. One vehicle: `cores` is {role: core} under one `Schedule`, every
    step is granted at once, and the steppers run in loop order until none can go further. A
    fleet: `cores` is {vehicle: {role: core}} under a `Fleet`, granted one step at a time as the
    clock does, with `observer` checking between the vehicles after each step.

    `swaps` maps a step to replacement cores ({app: core}), swapped in before that step as
    `nearsub swap --at-step` does: the grant stops before the step, the new core takes over
    through the same handover as a swapped-in process, and the grant goes on. `operator` replays
    operator overrides (app, topic leaf, from step, message), as their events in a log record.
    """
    fleet = schedule if isinstance(schedule, Fleet) else Fleet.single(schedule)
    crews = cores if isinstance(schedule, Fleet) else {None: cores}
    swaps = swaps or {}
    vehicle_of = {keys.app_name(v, role): v for v in crews for role in ORDER}

    def stepper(app: str, core: Core) -> Stepper:
        schedule = fleet.schedules[vehicle_of[app]]
        return Stepper(core, schedule, dt, max_steps, ends_itself=not fleet.shared)

    steppers = {app: stepper(app, crews[v][keys.split_app(app)[1]]) for app, v in vehicle_of.items()}
    for app, leaf, step, message in operator:
        steppers[app].override(leaf, message, step)
    messages: list[tuple[str, str, Message]] = []
    ends = Ends(fleet)
    states: dict[str, Message] = {}  # each vehicle's latest state, for the observer

    def consumers_of() -> dict[str, dict[str, list[str]]]:
        """app -> topic leaf -> the apps of its vehicle that consume it (again after a swap)."""
        return {
            app: {
                leaf: [a for a in steppers if vehicle_of[a] == v and leaf in steppers[a].core.inputs]
                for leaf in PRODUCER
            }
            for app, v in vehicle_of.items()
        }

    consumers = consumers_of()

    def run_until_quiet() -> None:
        """Run the steppers in loop order, each again only once it has new input, until none has."""
        due = set(steppers)
        while due:
            for app in steppers:
                if app not in due:
                    continue
                due.discard(app)
                for channel, message in steppers[app].run():
                    if channel == ACK:
                        if message.end is not None:
                            ends.request(vehicle_of[app], EndRequest(message.step, message.end, message.reason))
                            if not fleet.shared:
                                for other in steppers.values():
                                    other.end_after(message.step)
                        continue
                    messages.append((app, channel, message))
                    if channel == "state":
                        states[vehicle_of[app]] = message
                    for consumer in consumers[app].get(channel, ()):
                        if not steppers[consumer].receives(channel, message.step):
                            continue
                        if error := steppers[consumer].offer(channel, message):
                            raise RuntimeError(error)
                        due.add(consumer)
        for app, waiting in steppers.items():
            if missing := waiting.blocked():
                raise RuntimeError(f"{app} at step {waiting.step} is missing {missing}")

    step = 0  # the next step to grant
    while step < max_steps and ends.end is None:
        for app, core in swaps.get(step, {}).items():
            handover = steppers[app].handover(step)
            if handover is None:
                raise RuntimeError(f"{app} cannot hand over at step {step}")
            steppers[app] = stepper(app, core)
            steppers[app].take_over(handover, step)
            consumers = consumers_of()
        pauses = [pause - 1 for pause in swaps if step < pause < max_steps]
        target = step if fleet.shared else min([*pauses, max_steps - 1])
        for waiting in steppers.values():
            waiting.grant(target)
        run_until_quiet()
        if observer is not None and fleet.shared:
            found = observer.observe(target, states)
            messages.extend((ENCOUNTERS, EVENTS, event) for event in found.events)
            if found.end is not None:
                ends.request(None, EndRequest(target, found.end, found.reason))
        step = target + 1
    end = ends.end or time_limit_end(max_steps, dt)
    return InProcessResult(end.outcome, end.reason, end.step + 1, messages)
