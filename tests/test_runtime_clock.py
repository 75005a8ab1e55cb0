"""The clock's grants, pauses and stall detection (`ClockCore`), driven with a made-up wall clock."""

import pytest

from nearsub.common.runtime.clock import MAX_LAG, MAX_WARP, NAP, PACED_NAP, WARP_SAMPLE, ClockCore, GrantPolicy
from nearsub.common.runtime.lifecycle import ORDER, Schedule
from nearsub.common.runtime.messages import Ack, Control

DT = 0.05
TIMEOUT = 2.0


def clock(warp=0.0, max_steps=1000, helm_period=5, pause_at_step=None, dt=DT) -> ClockCore:
    core = ClockCore(Schedule({"helm": helm_period, "pid": 1, "sim": 1}), dt, warp, max_steps, TIMEOUT, pause_at_step)
    core.start(0.0)
    return core


def finish(core: ClockCore, step: int, roles=ORDER) -> None:
    """The apps in `roles` that run at `step` finish it, each with its done output."""
    for role in roles:
        if role not in core.progress.schedule.runners(step):
            continue
        if role == "helm":
            core.progress.record_output("desired", "helm", step)
        elif role == "pid":
            core.progress.record_output("input", "pid", step)
        else:
            core.progress.record_output("state", "sim", step + 1)  # x_{k+1} is labelled k + 1


def finish_up_to(core: ClockCore, last: int) -> None:
    for step in range(core.step, last + 1):
        finish(core, step)


def granted(core: ClockCore, now: float) -> int | None:
    advance = core.advance(now)
    assert advance.end is None, advance.end
    return None if advance.tick is None else advance.tick.step


def request(cmd: str, **args) -> Control:
    return Control(step=0, t=0.0, source="tool", cmd=cmd, args=args, request_id=f"{cmd}-{args}", reply_to="tool")


def test_warp_zero_grants_a_window_ahead_of_the_slowest_app():
    core = clock()
    assert granted(core, 0.0) == 19
    finish_up_to(core, 5)
    assert granted(core, 0.1) is None  # 25 is less than half a window beyond 19: no tick yet
    finish_up_to(core, 9)
    assert granted(core, 0.2) == 29
    finish(core, 10, roles=("helm", "pid"))  # the sim has not finished step 10
    assert core.progress.completed == 9 and granted(core, 0.3) is None


def test_the_grant_stops_at_the_time_limit_and_the_mission_ends_after_the_last_step():
    core = clock(max_steps=30)
    assert granted(core, 0.0) == 19
    finish_up_to(core, 15)
    assert granted(core, 0.1) == 29  # capped by the time limit, so granted at once
    finish_up_to(core, 29)
    end = core.advance(0.2).end
    assert (end.outcome, end.step, end.reason) == ("time_limit", 30, f"reached the time limit of {30 * DT:g} s")


def test_warp_n_grants_the_steps_whose_simulated_time_has_come():
    core = clock(warp=2.0)  # step k is due at k * 0.05 / 2 s
    assert granted(core, 0.0) == 0
    assert granted(core, 0.1) == 4
    finish_up_to(core, 4)
    assert granted(core, 0.11) is None
    assert granted(core, 0.2) == 8


def test_warp_changes_at_run_time_from_the_current_step_and_status_reports_it():
    core = clock(warp=2.0)
    assert granted(core, 0.0) == 0
    assert core.on_control(request("status"), 0.0)[0][1].data["achieved_warp"] is None
    for k in range(1, 41):  # 2 s of wall time at warp 2: the apps keep up
        finish_up_to(core, core.granted)
        granted(core, k * 0.05)
    finish_up_to(core, core.granted)
    [(_, status)] = core.on_control(request("status"), 2.0)
    assert status.data["warp"] == 2.0 and status.data["achieved_warp"] == pytest.approx(2.0, rel=0.05)
    assert status.data["step"] == 81
    [(_, reply)] = core.on_control(request("warp", warp=10), 2.0)
    assert reply.ok and reply.data["warp"] == 10.0
    # Rebased on the current step 81, due now; at warp 10 a tick carries at least 2 steps (0.01 s).
    assert granted(core, 2.0) is None
    assert granted(core, 2.01) == 83  # no jump: 0.01 s at warp 10 is 0.1 simulated seconds
    finish_up_to(core, 83)
    assert granted(core, 2.05) == 81 + 10  # 0.05 s at warp 10 is 0.5 simulated seconds, 10 steps
    for bad in (-1, "fast", float("nan"), float("inf"), 1e308, None, True):
        [(_, refused)] = core.on_control(request("warp", warp=bad), 2.2)
        assert not refused.ok and "warp: must be a number from 0 to 1e+06" in refused.error
    assert core.policy.warp == 10.0
    [(_, reply)] = core.on_control(request("warp", warp=0), 2.2)
    finish_up_to(core, core.granted)
    assert reply.ok and granted(core, 2.2) == 91 + 20  # warp 0: a window ahead at once
    [(_, fastest)] = core.on_control(request("warp", warp=MAX_WARP), 2.2)
    finish_up_to(core, core.granted)
    assert fastest.ok and granted(core, 2.3) == 111 + 20  # the pacing arithmetic stays finite


def test_pause_at_the_next_step_boundary_and_resume():
    core = clock()
    assert granted(core, 0.0) == 19
    assert core.on_control(request("pause"), 0.0) == []  # answered once reached
    finish_up_to(core, 18)
    assert core.advance(0.1).replies == [] and not core.paused
    finish(core, 19)
    advance = core.advance(0.2)
    assert core.paused and advance.tick is None
    [(to, reply)] = advance.replies
    assert to == "tool" and reply.ok and reply.data == {"step": 20}
    [(_, status)] = core.on_control(request("status"), 0.3)
    achieved = 20 * DT / 0.3  # 20 steps since the first sample, at 0.0
    assert status.data == {"step": 20, "t": 20 * DT, "paused": True, "warp": 0.0, "achieved_warp": achieved}
    assert granted(core, 0.4) is None  # paused: no grant
    [(_, resumed)] = core.on_control(request("resume"), 0.5)
    assert resumed.data == {"step": 20} and not core.paused
    assert granted(core, 0.5) == 39


def test_pause_at_a_given_step():
    core = clock(pause_at_step=7)
    assert granted(core, 0.0) == 6
    finish_up_to(core, 6)
    assert core.advance(0.1).replies == [] and core.paused  # the mission's own pause: no one to answer
    core.on_control(request("resume"), 0.2)
    assert granted(core, 0.2) == 26
    [(_, refused)] = core.on_control(request("pause", at=20), 0.3)
    assert not refused.ok and "granted up to 26" in refused.error
    assert core.on_control(request("pause", at=40), 0.3) == []
    finish_up_to(core, 20)
    assert granted(core, 0.4) == 39  # no further than the step before the pause
    finish_up_to(core, 39)
    [(_, reply)] = core.advance(0.5).replies
    assert reply.data == {"step": 40} and core.paused


@pytest.mark.parametrize("at", ["20", 2.5, True, None])
def test_a_pause_at_something_not_a_step_is_refused(at):
    core = clock()
    [(_, reply)] = core.on_control(request("pause", at=at), 0.0)
    assert not reply.ok and "'at' must be a step number" in reply.error
    assert core.pause_before is None


def test_an_unknown_command_is_refused():
    [(_, reply)] = clock().on_control(request("jump"), 0.0)
    assert not reply.ok and "jump" in reply.error


def test_a_stall_names_the_first_app_in_loop_order_that_has_not_finished_the_step():
    core = clock()
    granted(core, 0.0)
    finish_up_to(core, 4)
    finish(core, 5, roles=("helm",))
    assert core.advance(1.0).end is None
    end = core.advance(1.0 + TIMEOUT + 0.01).end
    assert end.outcome == "stalled" and end.step == 5
    assert end.reason == f"app 'pid' did not finish step 5 within {TIMEOUT:g} s (sim waiting on it)"


def test_an_earlier_end_request_wins_over_a_more_severe_later_one():
    core = clock()
    granted(core, 0.0)
    finish_up_to(core, 2)
    core.progress.record_ack(Ack(step=4, t=4 * DT, source="sim", end="collision"))
    core.progress.record_ack(Ack(step=3, t=3 * DT, source="pid", end="completed"))
    finish(core, 3, roles=("sim",))
    end = core.advance(0.1).end
    assert (end.outcome, end.step) == ("completed", 4)


def test_progress_restarts_the_stall_timer():
    core = clock()
    granted(core, 0.0)
    for k in range(5):
        finish(core, k)
        assert core.advance((k + 1) * 0.9 * TIMEOUT).end is None
    assert core.advance(5 * 0.9 * TIMEOUT + TIMEOUT + 0.01).end.outcome == "stalled"


def test_a_pause_longer_than_the_step_timeout_does_not_stall_on_resume():
    core = clock(pause_at_step=10)
    granted(core, 0.0)
    finish_up_to(core, 9)
    core.advance(0.1)
    assert core.paused
    assert core.advance(0.1 + 5 * TIMEOUT).end is None  # paused: nothing is owed
    core.on_control(request("resume"), 20 * TIMEOUT)
    assert granted(core, 20 * TIMEOUT) == 29
    assert core.advance(20.5 * TIMEOUT).end is None  # the timer restarted on resume
    end = core.advance(21 * TIMEOUT + 0.01).end
    assert end.outcome == "stalled" and "app 'helm' did not finish step 10" in end.reason


def test_the_wait_for_a_paced_step_is_not_a_stall():
    core = clock(warp=0.01, dt=1.0, helm_period=1)  # one step every 100 s
    assert granted(core, 0.0) == 0
    finish(core, 0)
    assert granted(core, 99.0) is None
    assert granted(core, 100.0) == 1
    assert core.advance(100.0 + TIMEOUT * 0.9).end is None
    assert core.advance(100.0 + TIMEOUT + 0.01).end.outcome == "stalled"


@pytest.mark.parametrize(
    ("first", "second", "expected"), [("completed", "collision", "collision"), ("time_limit", "collision", "collision")]
)
def test_the_most_severe_end_request_of_a_step_wins(first, second, expected):
    core = clock()
    granted(core, 0.0)
    finish_up_to(core, 2)
    core.progress.record_ack(Ack(step=3, t=3 * DT, source="pid", end=first, reason=first))
    assert core.advance(0.1).end is None  # the sim has still to finish step 3
    core.progress.record_ack(Ack(step=3, t=3 * DT, source="sim", end=second, reason=second))
    end = core.advance(0.2).end
    assert (end.outcome, end.reason, end.step) == (expected, expected, 4)


def test_an_error_ends_the_mission_at_once_though_its_step_never_completes():
    core = clock()
    granted(core, 0.0)
    finish_up_to(core, 2)
    core.progress.record_ack(Ack(step=3, t=3 * DT, source="sim", end="error", reason="server gone"))
    end = core.advance(0.1).end  # the helm and pid may wait for the sim's step 3 forever
    assert (end.outcome, end.reason, end.step) == ("error", "server gone", 4)


def test_claims_of_steps_not_granted_are_ignored_and_hold_no_memory():
    core = clock()
    assert granted(core, 0.0) == 19
    for step in range(20, 5020):  # forged done outputs, far beyond the grant
        core.progress.record_output("input", "pid", step)
        core.progress.record_output("state", "sim", step + 1)
    core.progress.record_ack(Ack(step=10**9, t=0.0, source="helm"))
    assert core.progress.done == {} and core.progress.completed == -1
    finish_up_to(core, 19)
    assert core.progress.completed == 19 and core.progress.done == {}


def test_the_clock_wakes_for_the_next_paced_step_or_the_stall_deadline_whichever_is_first():
    paced = clock(warp=2.0)
    granted(paced, 0.0)  # step 0 is due at once
    assert paced.wake_in(0.0) == pytest.approx(DT / 2.0)  # step 1 is due at dt / warp
    assert paced.wake_in(1.0) == 0.0  # overdue: act now
    flat_out = clock()
    assert granted(flat_out, 0.0) == 19
    assert flat_out.wake_in(0.0) == pytest.approx(0.25)  # owed, stall far off: the meter's sample
    assert flat_out.wake_in(TIMEOUT - 0.1) == pytest.approx(0.1)  # nothing done: the stall deadline
    finish_up_to(flat_out, 19)
    assert granted(flat_out, 0.5) == 39


# -- the grant policy as a pure function of progress and wall time ----------------------------


def test_a_warp_the_apps_cannot_hold_grants_up_to_the_window_in_batches_not_one_step():
    policy = GrantPolicy(DT, warp=50.0, max_steps=10_000, window=20)  # a step is due every 1 ms
    now = 10.0  # 10 000 steps are due; the apps have completed 100
    assert policy.extend(100, 110, now, None, None) == 120  # the window, as at warp 0
    assert policy.extend(105, 120, now, None, None) is None  # 5 steps more: less than a batch
    assert policy.extend(110, 120, now, None, None) == 130
    # Held by the window, not the warp: nothing to wake up for but progress.
    assert policy.release(110, 130, None, None) is None


def test_a_warp_the_apps_hold_releases_the_due_steps_a_tick_interval_at_a_time():
    policy = GrantPolicy(DT, warp=50.0, max_steps=10_000, window=20)
    assert policy.batch == 10  # 10 ms of wall time at 1 ms a step
    assert policy.extend(-1, -1, 0.0, None, None) is None  # only step 0 is due
    assert policy.release(-1, -1, None, None) == pytest.approx(9 * DT / 50.0)
    assert policy.extend(-1, -1, 9 * DT / 50.0, None, None) == 9
    assert policy.extend(8, 9, 0.0185, None, None) is None  # 18 due: 9 more, less than a batch
    assert policy.extend(8, 9, 0.0190, None, None) == 19
    # The last step is granted once it is due, though the batch is not whole.
    short = GrantPolicy(DT, 50.0, max_steps=5, window=20)
    assert short.extend(-1, -1, 0.0039, None, None) is None and short.extend(-1, -1, 0.0040, None, None) == 4
    slow = GrantPolicy(DT, warp=1.0, max_steps=10_000, window=20)
    assert slow.batch == 1  # a step every 50 ms: each on its own tick


def test_a_schedule_the_apps_fell_behind_slips_so_they_do_not_sprint_afterwards():
    policy = GrantPolicy(DT, warp=1.0, max_steps=10_000, window=100)  # a window wide enough to see it
    assert policy.extend(-1, -1, 0.0, None, None) == 0
    # 10 s later the apps have done 10 steps (200 were due): the schedule slips to MAX_LAG late.
    limit = policy.limit(9, 10.0, None, None)
    assert limit == 10 + round(MAX_LAG / DT) and policy.wall0 == pytest.approx(10.0 - MAX_LAG - 10 * DT)
    # Keeping up from there, at most MAX_LAG of simulated time at warp 1 is granted at once.
    assert policy.limit(limit, 10.0, None, None) == limit


def test_a_clock_behind_its_warp_does_not_spin():
    core = clock(warp=50.0)
    assert granted(core, 0.0) is None  # step 0 alone is due: less than a batch
    assert core.wake_in(0.0) == pytest.approx(9 * DT / 50.0)
    assert granted(core, 0.5) == 19  # 250 steps are due: the window
    assert core.wake_in(0.5) == pytest.approx(WARP_SAMPLE)  # not 0: only progress moves the grant
    finish_up_to(core, 9)
    assert granted(core, 0.6) == 29


def test_the_clock_naps_through_its_mail_only_while_the_apps_have_granted_steps_to_run():
    flat_out = clock()
    assert granted(flat_out, 0.0) == 19
    assert flat_out.nap(0.0) == pytest.approx(NAP)  # 20 steps granted: their outputs can wait
    finish_up_to(flat_out, 12)
    assert flat_out.nap(0.01) == 0.0  # 7 left, a grant is due: read the mail as it comes
    paced = clock(warp=2.0)
    granted(paced, 0.0)
    assert paced.nap(0.0) == pytest.approx(DT / 2.0)  # nothing can be granted before step 1 is due
    slow = clock(warp=0.5)
    assert granted(slow, 0.0) == 0 and slow.nap(0.0) == pytest.approx(PACED_NAP)  # step 1 at 0.1 s: answer within
    short = clock(max_steps=15)
    assert granted(short, 0.0) == 14 and short.nap(0.0) == 0.0  # the end is near: do not miss it
    fleet = ClockCore(Schedule({"helm": 5, "pid": 1, "sim": 1}), DT, 0.0, 1000, TIMEOUT)
    fleet.policy.window = 1  # a fleet's clock grants one step at a time
    fleet.start(0.0)
    assert granted(fleet, 0.0) == 0 and fleet.nap(0.0) == 0.0
