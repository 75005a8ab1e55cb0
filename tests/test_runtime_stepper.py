"""The lock-step rules of `Stepper` and `run_inprocess`, with small fake cores and no processes."""

import pytest

from conftest import ALPHA
from nearsub.common.mission.cores import HelmCore, PidCore, SimCore, build_cores
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.lifecycle import (
    ACK,
    EVENTS,
    EndRequest,
    Iteration,
    Schedule,
    Stepper,
    control_reply,
    first_end,
    run_inprocess,
)
from nearsub.common.runtime.messages import Control, Desired, Event, Input, State, encode

DT = 0.1


def state(step: int) -> State:
    return State(step=step, t=step * DT, source="sim", u=1.0, v=0.0, r=0.0, x=float(step), y=0.0, psi=0.0)


def desired(step: int) -> Desired:
    return Desired(step=step, t=step * DT, source="helm", u_d=1.0, psi_d=0.1 * step)


class FakePid:
    """A pid that records its mail and answers each step with an input, unless told otherwise."""

    role = "pid"
    inputs = ("state", "desired")
    outputs = ("input",)

    def __init__(self, end_at: int | None = None, silent_at: int | None = None, fail: Exception | None = None):
        self.end_at, self.silent_at, self.fail = end_at, silent_at, fail
        self.mail: list[tuple[int, tuple[str, ...]]] = []
        self.pending: tuple[str, ...] = ()
        self.count = 0

    def startup(self):
        return []

    def new_mail(self, mail):
        self.pending = tuple(sorted(mail))

    def iterate(self, step, t):
        if self.fail is not None:
            raise self.fail
        self.mail.append((step, self.pending))
        self.count += 1
        result = Iteration()
        if step != self.silent_at:
            result.outputs.append(("input", Input(step=step, t=t, source="pid", X_prop=float(self.count), delta_r=0.0)))
        result.events.append(Event(step=step, t=t, source="pid", kind="info", detail="ran"))
        if step == self.end_at:
            result.end, result.reason = "completed", "done"
        return result

    def progress(self):
        return {"count": self.count}

    def restore(self, progress):
        self.count = progress["count"]


def stepper(core=None, helm_period=1, max_steps=100, **kwargs) -> Stepper:
    schedule = Schedule({"helm": helm_period, "pid": 1, "sim": 1})
    return Stepper(core or FakePid(), schedule, DT, max_steps, **kwargs)


def feed(s: Stepper, k: int, helm_period: int = 1) -> None:
    """The inputs of step k, as the sim and helm publish them once step k - 1 is done."""
    assert s.offer("state", state(k)) is None
    if k % helm_period == 0:
        assert s.offer("desired", desired(k)) is None


def drive(s: Stepper, steps, helm_period: int = 1) -> list:
    """Feed each step's inputs and run; everything published, as (channel, message)."""
    published = []
    for k in steps:
        feed(s, k, helm_period)
        published += s.run()
    return published


def inputs(published) -> list[int]:
    return [m.step for c, m in published if c == "input"]


def test_a_step_runs_once_granted_and_its_inputs_have_arrived():
    s = stepper()
    s.offer("state", state(0))
    s.offer("desired", desired(0))
    assert s.run() == [] and s.step == 0  # nothing granted

    s = stepper()
    s.grant(5)
    s.offer("state", state(0))
    assert s.run() == [] and s.blocked() == ["desired"]
    s.offer("desired", desired(0))
    assert [(c, m.step) for c, m in s.run()] == [("input", 0), (EVENTS, 0)]
    assert s.step == 1 and s.blocked() == ["state", "desired"]


def test_no_step_past_the_grant():
    s = stepper()
    s.grant(3)
    assert inputs(drive(s, range(5))) == [0, 1, 2, 3]
    assert s.step == 4 and s.blocked() == []  # step 4 is not granted
    s.grant(4)
    assert inputs(s.run()) == [4]


def test_the_output_of_a_slower_app_is_held_and_delivered_once():
    core = FakePid()
    s = stepper(core, helm_period=5)
    s.grant(6)
    drive(s, range(7), helm_period=5)
    assert core.mail == [
        (0, ("desired", "state")),
        (1, ("state",)),
        (2, ("state",)),
        (3, ("state",)),
        (4, ("state",)),
        (5, ("desired", "state")),
        (6, ("state",)),
    ]


def test_a_slower_producer_is_waited_for_at_its_own_steps():
    s = stepper(helm_period=5)
    s.grant(6)
    s.offer("desired", desired(0))
    for k in range(6):
        s.offer("state", state(k))
        s.run()
    assert s.step == 5 and s.blocked() == ["desired"]
    s.offer("desired", desired(5))
    assert inputs(s.run()) == [5]


def test_an_end_request_goes_out_before_its_step_outputs_and_stops_the_app():
    s = stepper(FakePid(end_at=2))
    s.grant(9)
    published = drive(s, range(4))
    assert [(c, m.step) for c, m in published][-3:] == [(ACK, 2), ("input", 2), (EVENTS, 2)]
    ack = published[-3][1]
    assert ack.end == "completed" and ack.reason == "done"
    assert s.step == 3 and inputs(published) == [0, 1, 2]


class ThenPid(FakePid):
    """A pid whose step leaves work for `Iteration.then` (as the sim leaves its forces query)."""

    def __init__(self, fail: Exception | None = None):
        super().__init__()
        self.then_fail = fail
        self.then_ran: list[int] = []

    def iterate(self, step, t):
        result = super().iterate(step, t)

        def later():
            self.then_ran.append(step)
            if self.then_fail is not None:
                raise self.then_fail
            return Iteration(events=[Event(step=step, t=t, source="pid", kind="info", detail="later")])

        result.then = later
        return result


def test_then_runs_after_its_step_outputs_are_out_and_adds_no_ack():
    core = ThenPid()
    s = stepper(core)
    s.grant(9)
    feed(s, 0)
    outputs = s.produce()
    assert next(outputs)[0] == "input" and core.then_ran == []  # published before `then` starts
    rest = [(c, m.detail) for c, m in outputs]
    assert core.then_ran == [0] and rest == [(EVENTS, "ran"), (EVENTS, "later")]
    assert s.step == 1


def test_a_recoverable_failure_in_then_ends_the_mission_after_the_step_outputs():
    s = stepper(ThenPid(fail=TimeoutError("server gone")), recoverable=(TimeoutError,))
    s.grant(9)
    published = drive(s, range(3))
    assert [c for c, _ in published] == ["input", EVENTS, ACK, EVENTS]
    ack = published[2][1]
    assert ack.end == "error" and "server gone" in ack.reason and s.step == 1


def test_an_end_request_of_another_app_stops_after_its_step():
    s = stepper()
    s.grant(9)
    s.end_after(4)
    assert inputs(drive(s, range(7))) == [0, 1, 2, 3, 4]


def test_a_step_without_the_done_output_is_acknowledged_explicitly():
    s = stepper(FakePid(silent_at=1))
    s.grant(2)
    channels = [(c, m.step) for c, m in drive(s, range(3))]
    assert [step for c, step in channels if c == ACK] == [1]  # the others are acknowledged by their input
    assert ("input", 1) not in channels


def test_a_recoverable_failure_ends_the_mission_with_an_error():
    s = stepper(FakePid(fail=TimeoutError("server gone")), recoverable=(TimeoutError,))
    s.grant(2)
    (ack_channel, ack), (event_channel, event) = drive(s, range(2))
    assert ack_channel == ACK and ack.end == "error" and ack.reason == "server gone"
    assert event_channel == EVENTS and event.kind == "error" and event.detail == "server gone"
    assert s.step == 1


def test_any_other_failure_propagates():
    s = stepper(FakePid(fail=ValueError("bug")), recoverable=(TimeoutError,))
    s.grant(0)
    with pytest.raises(ValueError, match="bug"):
        drive(s, range(1))


def test_a_handover_continues_without_skipping_or_repeating_a_step():
    plain = stepper()
    plain.grant(7)
    expected = [encode(m) for c, m in drive(plain, range(8)) if c == "input"]

    old = stepper()
    old.grant(3)  # the clock pauses before step 4
    before = [encode(m) for c, m in drive(old, range(5)) if c == "input"]
    assert old.step == 4 and old.handover(3) is None  # step 3 has passed
    handover = old.handover(4)
    assert handover is not None
    new = stepper()
    new.take_over(handover, 4)
    new.grant(7)  # resumed
    after = [encode(m) for c, m in new.run() + drive(new, range(5, 8)) if c == "input"]
    assert before + after == expected


@pytest.mark.parametrize("role", ["pid", "sim"])
@pytest.mark.parametrize("step", [100, 103])
def test_inprocess_swap_of_the_pid_or_the_sim_changes_nothing(role, step):
    """At a helm step (100) the pid's desired and the sim's input are made within the step, after
    the pause, and reach the new app; at 103 the pid goes on from the desired of step 100."""
    mission = load_mission(ALPHA, ["time_limit=10"])
    schedule = Schedule(mission.periods())
    plain = run_inprocess(build_cores(mission), schedule, mission.dt, mission.max_steps)
    core = PidCore(mission) if role == "pid" else SimCore(mission)
    swapped = run_inprocess(build_cores(mission), schedule, mission.dt, mission.max_steps, {step: {role: core}})
    assert [encode(m) for _, _, m in swapped.messages] == [encode(m) for _, _, m in plain.messages]


def test_a_grant_further_ahead_than_the_clocks_window_is_refused():
    """A forged tick far ahead would let the apps run past the clock's pacing and its checks."""
    mission = load_mission(ALPHA, ["time_limit=10"])
    waiting = Stepper(
        build_cores(mission)["pid"], Schedule(mission.periods()), mission.dt, mission.max_steps, window=20
    )
    assert waiting.grant(19) is None and waiting.granted == 19  # the clock's first grant
    assert "tick to step 150 ignored" in waiting.grant(150) and waiting.granted == 19


def test_first_end_takes_the_earliest_step_then_the_most_severe():
    completed = EndRequest(5, "completed")
    assert first_end(None, completed) == completed
    assert first_end(completed, EndRequest(6, "collision")) == completed
    assert first_end(completed, EndRequest(5, "collision")).outcome == "collision"
    assert first_end(EndRequest(5, "collision"), EndRequest(5, "time_limit")).outcome == "collision"
    assert first_end(completed, EndRequest(4, "time_limit")).step == 4


def test_inprocess_swap_at_a_step_the_helm_skips_changes_nothing():
    mission = load_mission(ALPHA, ["time_limit=10"])
    schedule = Schedule(mission.periods())
    plain = run_inprocess(build_cores(mission), schedule, mission.dt, mission.max_steps)
    swapped = run_inprocess(
        build_cores(mission), schedule, mission.dt, mission.max_steps, {103: {"helm": HelmCore(mission)}}
    )
    assert mission.apps.helm.period > 1 and 103 % mission.apps.helm.period != 0
    assert [encode(m) for _, _, m in swapped.messages] == [encode(m) for _, _, m in plain.messages]
    assert (swapped.outcome, swapped.steps) == (plain.outcome, plain.steps) == ("time_limit", 200)


def test_inprocess_names_the_app_whose_input_never_comes():
    mission = load_mission(ALPHA, ["time_limit=10"])
    cores = build_cores(mission)
    cores["sim"].startup = lambda: []  # x_0 never published
    with pytest.raises(RuntimeError, match=r"helm at step 0 is missing \['state'\]"):
        run_inprocess(cores, Schedule(mission.periods()), mission.dt, mission.max_steps)


def test_inprocess_ends_after_the_step_of_the_first_end_request():
    mission = load_mission(ALPHA, ["time_limit=10"])
    cores = build_cores(mission)
    iterate = cores["pid"].iterate

    def ending(step, t):
        result = iterate(step, t)
        if step == 42:
            result.end, result.reason = "collision", "pretend"
        return result

    cores["pid"].iterate = ending
    result = run_inprocess(cores, Schedule(mission.periods()), mission.dt, mission.max_steps)
    assert (result.outcome, result.reason, result.steps) == ("collision", "pretend", 43)
    assert [m.step for m in result.topic("input")][-1] == 42
    assert [m.step for m in result.topic("state")][-1] == 43  # the sim still ran step 42


def test_a_control_reply_answers_its_request():
    request = Control(step=0, t=0.0, source="tool", cmd="status", request_id="r1", reply_to="tool")
    reply = control_reply(request, "helm-1", 7, DT, data={"a": 1})
    assert (reply.request_id, reply.ok, reply.source, reply.step, reply.data) == ("r1", True, "helm-1", 7, {"a": 1})
    assert reply.t == pytest.approx(0.7)
    refused = control_reply(request, "helm-1", 7, DT, ok=False, error="no")
    assert not refused.ok and refused.error == "no" and refused.data == {}


def test_inputs_off_the_producers_sequence_are_refused_and_the_app_runs_on():
    """A far-future step, a stale one, one off the producer's period or from the wrong source is
    an error text: nothing is held for it and the steps run as if it never came."""
    s = stepper(helm_period=5)
    s.grant(9)
    refused = [
        ("desired", desired(10**9), "step 1000000000 ignored"),
        ("desired", desired(5), "the next is step 0"),
        ("desired", Desired(step=0, t=0.0, source="tap", u_d=1.0, psi_d=0.0), "only 'helm' publishes"),
    ]
    for leaf, message, text in refused:
        assert text in s.offer(leaf, message)
    assert s.offer("desired", desired(0)) is None
    assert "the next is step 5" in s.offer("desired", desired(3))
    assert "the next is step 5" in s.offer("desired", desired(0))
    for k in range(6):
        assert s.offer("state", state(k)) is None
        assert "the next is step" in s.offer("state", state(k + 7))
        s.run()
    assert s.step == 5 and s.blocked() == ["desired"]
    assert s.offer("desired", desired(5)) is None
    assert inputs(s.run()) == [5]
    assert s.inbox.held["desired"].step == 5 and len(s.inbox.held) == 2


class MailPid(FakePid):
    """A fake pid that also records the desired heading it was given at each step."""

    def __init__(self):
        super().__init__()
        self.psi_d: list[tuple[int, float]] = []
        self.desired = None

    def new_mail(self, mail):
        super().new_mail(mail)
        self.desired = mail.get("desired", self.desired)

    def iterate(self, step, t):
        self.psi_d.append((step, self.desired.psi_d))
        return super().iterate(step, t)


def test_an_operator_override_holds_from_the_next_step_and_survives_a_handover():
    steer = Desired(step=0, t=0.0, source="operator", u_d=1.0, psi_d=9.0)
    old = stepper(MailPid())
    old.grant(3)
    drive(old, range(3))
    event = old.override("desired", steer)
    assert (event.kind, event.step, event.data["leaf"]) == ("info", 3, "desired")
    assert event.detail == "operator desired from step 3: u_d=1.0, psi_d_deg=515.662"  # 9 rad, for people
    assert event.data["message"]["psi_d"] == 9.0  # the raw message, as it went
    drive(old, range(3, 5))  # the pause before step 4
    new = stepper(MailPid())
    new.take_over(old.handover(4), 4)
    new.grant(8)
    new.run()
    drive(new, range(5, 9))
    seen = old.core.psi_d + new.core.psi_d
    assert seen == [(0, 0.0), (1, 0.1), (2, 0.2), (3, 9.0), (4, 9.0), (5, 9.0), (6, 9.0), (7, 9.0), (8, 9.0)]

    # The replay: the same override given with its step before the run.
    replay = stepper(MailPid())
    replay.override("desired", steer, 3)
    replay.grant(8)
    drive(replay, range(9))
    assert replay.core.psi_d == seen
    assert len(replay.overrides["desired"]) == 1
