"""The functional core run in one process: the reference the multi-process run must equal."""

import numpy as np

from conftest import ALPHA
from nearsub.common.mission.cores import build_cores
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.lifecycle import Schedule, run_inprocess


def run(overrides=()):
    mission = load_mission(ALPHA, list(overrides))
    return mission, run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)


def test_alpha_completes_and_reaches_every_waypoint():
    mission, result = run()
    assert result.outcome == "completed"
    reached = [m for _, leaf, m in result.messages if leaf == "events" and m.kind == "waypoint"]
    assert len(reached) == 6
    final = result.topic("state")[-1]
    assert np.hypot(final.x - 0.0, final.y + 20.0) < 2.0  # captured home within 2 m
    # MOOS-IvP takes about 446 s; our dynamic REMUS model is within 10 % of that.
    assert 380 < final.t < 490


def test_every_step_has_exactly_one_state_and_input():
    mission, result = run(["time_limit=30"])
    states = [m.step for m in result.topic("state")]
    inputs = [m.step for m in result.topic("input")]
    desired = [m.step for m in result.topic("desired")]
    assert states == list(range(result.steps + 1))
    assert inputs == list(range(result.steps))
    assert desired == list(range(0, result.steps, mission.apps.helm.period))


def test_helm_period_changes_the_schedule_not_the_protocol():
    _, every = run(["time_limit=30", "apps.helm.period=1"])
    _, fifth = run(["time_limit=30", "apps.helm.period=5"])
    assert len(every.topic("desired")) == 5 * len(fifth.topic("desired"))
    assert every.steps == fifth.steps


def test_schedule_labels():
    schedule = Schedule({"helm": 5, "pid": 1, "sim": 1})
    assert [schedule.expected_label("desired", k, "pid") for k in range(7)] == [0, 0, 0, 0, 0, 5, 5]
    assert schedule.expected_label("state", 7, "pid") == 7
    # The helm (period 5) reads every 5th state and forces, on their feeds; the pid every state.
    assert schedule.expected_label("state", 7, "helm") == 5
    assert schedule.stride("state", "helm") == schedule.stride("forces", "helm") == 5
    assert schedule.stride("state", "pid") == 1 and schedule.feeds("state") == (5,) and schedule.feeds("forces") == (5,)
    assert schedule.feeds("input") == () and schedule.feeds("desired") == ()
    # Not for a period that is no multiple of the producer's, nor for an operator's topic.
    odd = Schedule({"helm": 5, "pid": 2, "sim": 2})
    assert odd.stride("state", "helm") == 2 and odd.feeds("state") == ()
    assert Schedule({"helm": 1, "pid": 3, "sim": 1}).feeds("desired") == ()
    assert schedule.runners(10) == ["helm", "pid", "sim"] and schedule.runners(11) == ["pid", "sim"]


def test_every_lock_stepped_input_of_a_core_is_among_its_topics_consumers():
    """`Schedule.feeds` asks `CONSUMERS` who reads a topic: a core reading one it does not list
    would never get that topic's feed."""
    from nearsub.common.runtime.lifecycle import CONSUMERS, PRODUCER
    from nearsub.common.surrogate.model import load_surrogate

    nuv = ALPHA.parent / "overtake_stern_nuv.toml"
    for mission in (load_mission(ALPHA), load_mission(nuv)):
        surrogate = load_surrogate(mission.surrogate.model or None) if mission.needs_surrogate else None
        for role, core in build_cores(mission, surrogate).items():
            for leaf in core.inputs:
                assert leaf not in PRODUCER or role in CONSUMERS[leaf], (role, leaf)
