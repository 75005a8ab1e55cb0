"""The helm: objective functions and their arbitration, conditions, flags, modes, pokes, includes,
and the existing missions' decisions."""

import json
import math

import numpy as np
import pytest

from conftest import ROOT, nearsub
from helpers import finish, helm_trace, log_path, per_topic, poke_while_paused, run_with_poke, trace_differences
from nearsub.common.autonomy import helm, ivp, logic
from nearsub.common.mission.cores import build_cores, run_mission
from nearsub.common.mission.schema import MissionError, load_mission, mission_from_dict
from nearsub.common.physics.vehicles import get_vehicle
from nearsub.common.runtime.lifecycle import Schedule, run_inprocess
from nearsub.common.runtime.logfile import read_log
from nearsub.common.runtime.messages import Poke, encode

MISSIONS = ROOT / "missions"
DECISIONS = ROOT / "tests" / "data" / "helm-decisions.json"
REMUS = get_vehicle("remus100")


def spec(kind, name, **fields):
    return {"type": kind, "name": name, **fields}


def heading_mission(behaviours, variables=None, modes=None, time_limit=20.0):
    """A REMUS 100 in open water with the given behaviour list."""
    return mission_from_dict(
        {
            "name": "helmtest",
            "time_limit": time_limit,
            "start": {"speed": 1.0},
            "environment": {"submarine": False},
            "apps": {"helm": {"behaviours": behaviours, "variables": variables or {}, "modes": modes or []}},
        }
    )


def make_helm(mission):
    h = mission.apps.helm
    rules = tuple(rule.rule() for rule in h.modes)
    return helm.Helm(h.behaviour_specs(), h.variables, rules, mission.vehicle_model, mission.environment.u_sub)


STATE = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def test_the_higher_priority_wins_where_objectives_conflict_and_both_count_where_they_do_not():
    east = spec("constant_heading", "east", heading_deg=0.0, priority=100.0)
    north = spec("constant_heading", "north", heading_deg=90.0, priority=200.0)
    slow = spec("constant_speed", "slow", speed=0.5)
    decision = make_helm(heading_mission([east, north, slow])).iterate(STATE, 0.0)
    assert decision.active == ["north", "east", "slow"]  # by priority, then declaration
    assert decision.choice.psi == pytest.approx(math.radians(90.0))
    assert decision.choice.u == pytest.approx(0.5)  # the heading behaviours are indifferent to speed
    swapped = make_helm(heading_mission([{**east, "priority": 300.0}, north])).iterate(STATE, 0.0)
    assert swapped.choice.psi == 0.0 and swapped.winner == "east"


def test_equal_priorities_go_to_the_behaviour_declared_first():
    a = spec("constant_heading", "a", heading_deg=-30.0)
    b = spec("constant_heading", "b", heading_deg=30.0)
    assert make_helm(heading_mission([a, b])).iterate(STATE, 0.0).winner == "a"
    assert make_helm(heading_mission([b, a])).iterate(STATE, 0.0).winner == "b"


def test_a_single_objective_is_obeyed_exactly_not_rounded_to_the_grid():
    objective = ivp.peak_objective(0.123456789, 1.23456)
    choice = ivp.arbitrate([(100.0, objective)], 2.5)
    assert (choice.psi, choice.u) == (0.123456789, 1.23456)


def test_a_compromise_off_every_peak_comes_from_the_grid():
    """A heading-only and a speed-only objective: each peak keeps the other's variable where the
    vehicle is, so the best decision, both at once, is a grid cell."""
    heading = ivp.Objective((0.5, 1.0), heading=ivp.Zaic(0.5, 0.0, math.pi, circular=True))
    speed = ivp.Objective((0.0, 1.5), speed=ivp.Zaic(1.5, 0.0, 1.0))
    choice = ivp.arbitrate([(1.0, heading), (1.0, speed)], 2.0)
    assert choice.winner == -1 and choice.u == 1.5
    assert abs(choice.psi - 0.5) <= math.radians(ivp.HEADING_STEP_DEG) / 2


def test_a_table_read_on_the_grid_equals_its_pointwise_reading():
    table = ivp.Table(np.radians([0.0, 5.0, -5.0, 90.0, 180.0, -90.0]), np.array([1.2, 2.4]), np.eye(6, 2) + 0.1)
    headings, speeds = ivp.decision_grid(2.48)
    assert np.allclose(table.on_grid(2.48), table(headings[:, None], speeds[None, :]), rtol=0, atol=1e-12)


def test_the_arbitration_scores_its_choice_as_the_objectives_themselves_do():
    """Tables and ZAICs mixed: the chosen decision's utility is the weighted sum of each objective
    read at it alone (to the bit for a peak, summed in the same order), and no grid cell or peak
    scores more."""
    rng = np.random.default_rng(7)
    headings, speeds = ivp.decision_grid(2.48)
    for _ in range(40):
        table = ivp.Table(rng.uniform(-math.pi, math.pi, 9), np.array([1.24, 2.48]), rng.uniform(0, 1, (9, 2)))
        objectives = [
            (rng.uniform(1, 300), ivp.Objective(None, table=table)),
            (rng.uniform(1, 300), ivp.peak_objective(rng.uniform(-4, 4), rng.uniform(0, 2.4))),
            (rng.uniform(1, 300), ivp.Objective((0.2, 1.0), heading=ivp.Zaic(0.2, 0.1, 1.0, 0.3, circular=True))),
        ]
        current = (rng.uniform(-3, 3), rng.uniform(0, 2.4))
        choice = ivp.arbitrate(objectives, 2.48, current)
        total = sum(w * o(np.array([choice.psi]), np.array([choice.u])) for w, o in objectives)[0]
        if choice.winner == -1 and (choice.psi, choice.u) != current:
            assert choice.utility == pytest.approx(total, rel=0, abs=1e-9)
        else:
            assert choice.utility == total
        grid = sum(w * o(headings[:, None], speeds[None, :]) for w, o in objectives)
        peaks = [o.peak for _, o in objectives if o.peak is not None] + [current]
        best = max(grid.max(), *(sum(w * o(*p) for w, o in objectives) for p in peaks))
        assert choice.utility >= best - 1e-9


def test_hull_avoidance_predicts_that_turning_in_beside_the_hull_collides():
    """1.2 m off the parallel middle body at U_sub: heading in scores 0, heading along or out 1."""
    situation = helm.Situation(np.array([1.5, 0.0, 0.0, -3.44, 6.5, 0.0]), 0.0, {}, REMUS, 1.5)
    avoid = helm.HullAvoidanceSpec(type="hull_avoidance", name="avoid", min_clearance=0.2, safe_clearance=0.45)
    table = helm.hull_avoidance(avoid, situation, {}).objective.table
    assert table(math.radians(-60.0), 2.0) == 0.0
    assert table(0.0, 1.5) == 1.0 and table(math.radians(60.0), 2.0) == 1.0


def test_conditions_parse_and_evaluate():
    c = logic.parse_condition("DEPLOY == true and DEPTH < 10 or MODE = A:B")
    assert c.holds({"DEPLOY": "true", "DEPTH": 5.0})
    assert not c.holds({"DEPLOY": "true", "DEPTH": 15.0})
    assert c.holds({"MODE": "A:B"})
    assert not c.holds({})  # a condition on a variable with no value is false
    with pytest.raises(ValueError, match="not 'NAME op VALUE'"):
        logic.parse_condition("DEPLOY is true")


def test_hierarchical_modes_build_a_path():
    rules = (
        logic.ModeRule("MODE", "ACTIVE", None, (logic.parse_condition("DEPLOY == true"),), "INACTIVE"),
        logic.ModeRule("MODE", "SURVEYING", "ACTIVE", (logic.parse_condition("RETURN != true"),), "RETURNING"),
    )
    assert logic.evaluate_modes(rules, {"DEPLOY": "true", "RETURN": "false"}) == {"MODE": "ACTIVE:SURVEYING"}
    assert logic.evaluate_modes(rules, {"DEPLOY": "true", "RETURN": "true"}) == {"MODE": "ACTIVE:RETURNING"}
    assert logic.evaluate_modes(rules, {"DEPLOY": "false"}) == {"MODE": "INACTIVE"}


def test_flags_are_posted_on_transitions_and_seen_from_the_next_iteration():
    timer = spec(
        "timer",
        "t",
        duration=1.0,
        condition=["GO == true"],
        runflag={"RUN": 1},
        idleflag={"IDLE": 1},
        endflag={"DONE": True},
    )
    h = make_helm(heading_mission([timer], variables={"GO": False}))
    first = h.iterate(STATE, 0.0)
    assert [(n, v) for n, v, _ in first.postings] == [("IDLE", 1.0)]
    assert h.iterate(STATE, 0.25).postings == []  # still idle: nothing new
    h.poke({"GO": True})
    assert [(n, v) for n, v, _ in h.iterate(STATE, 0.5).postings] == [("RUN", 1.0)]
    done = h.iterate(STATE, 1.5)
    assert [(n, v) for n, v, _ in done.postings] == [("DONE", "true")]
    assert h.variables["DONE"] == "true" and h.state == ["complete"]


def test_a_poke_switches_behaviours_at_the_next_helm_step_and_replays():
    """DIRECTION picks the behaviour; a poke at step 101 takes effect at the helm's step 105."""
    mission = heading_mission(
        [
            spec("constant_heading", "east", heading_deg=0.0, condition=["DIRECTION == east"]),
            spec("constant_heading", "north", heading_deg=90.0, condition=["DIRECTION == north"]),
        ],
        variables={"DIRECTION": "east"},
    )
    result = run_with_poke(mission, {"DIRECTION": "north"}, at_step=101)
    headings = {m.step: m.psi_d for m in result.topic("desired")}
    assert headings[100] == 0.0 and headings[105] == pytest.approx(math.pi / 2)
    winners = {m.step: m.winner for m in result.topic("helm")}
    assert winners[100] == "east" and winners[105] == "north"


def test_two_pokes_due_at_one_step_are_merged_in_order():
    mission = heading_mission([spec("constant_speed", "s", speed=1.0, condition=["A == 2", "B == 3"])], {"A": 0})
    first = Poke(step=0, t=0.0, source="operator", values={"A": 1, "B": 3})
    second = Poke(step=0, t=0.0, source="operator", values={"A": 2})
    result = run_inprocess(
        build_cores(mission),
        Schedule(mission.periods()),
        mission.dt,
        mission.max_steps,
        operator=[("helm", "poke", 50, first), ("helm", "poke", 50, second)],
    )
    speeds = {m.step: m.u_d for m in result.topic("desired")}
    assert speeds[45] == 0.0 and speeds[50] == 1.0


def test_the_legacy_waypoint_mission_keeps_its_decisions():
    """The decisions recorded from the helm before the arbitration existed (tests/data)."""
    check_reference("alpha")


@pytest.mark.slow
@pytest.mark.timeout(1200)
@pytest.mark.parametrize(
    "name",
    ["overtake_stern_standard", "overtake_stern_nuv", "octagon_standard", "octagon_modified", "lateral_approach"],
)
def test_the_scenario_missions_keep_their_decisions(name):
    check_reference(name)


def test_a_waypoint_moved_1_cm_fails_the_pinned_decisions(tmp_path):
    """The tolerances of `check_reference` see a real change: alpha with its first waypoint 1 cm east."""
    moved = tmp_path / "alpha.toml"
    text = (MISSIONS / "alpha.toml").read_text()
    moved.write_text(text.replace("points = [[60.0, -40.0],", "points = [[60.01, -40.0],", 1))
    assert moved.read_text() != text
    differences = trace_differences(helm_trace(moved), json.loads(DECISIONS.read_text())["alpha"])
    assert any("/samples/helm/desired" in d and "psi_d" in d for d in differences), differences


def check_reference(name):
    """The mission's helm decisions against tests/data/helm-decisions.json, pinned on another machine
    (`python tests/pin_helm_decisions.py NAME`): how it ended and its step count, the count and
    content of every event, and evenly sampled desired (u_d, psi_d), helm progress (behaviour, leg,
    waypoint) and state messages, integers and strings exactly, floats to TRACE_ATOL + TRACE_RTOL |x|
    (helpers: a CPU's last-bit differences stay below 1e-11, a waypoint moved 1 cm or a PID gain
    changed 1 % moves them by 1e-3 and more)."""
    reference = json.loads(DECISIONS.read_text())[name]
    assert trace_differences(helm_trace(MISSIONS / f"{name}.toml"), reference) == []


def test_includes_resolve_relative_to_the_including_file(tmp_path):
    (tmp_path / "shared").mkdir()
    (tmp_path / "shared" / "safety.toml").write_text(
        '[[apps.helm.behaviours]]\ntype = "op_region"\nname = "region"\n'
        "polygon = [[-100.0, -100.0], [100.0, -100.0], [100.0, 100.0]]\n"
        "[apps.helm.variables]\nDEPLOY = true\n"
    )
    (tmp_path / "m.toml").write_text(
        'include = ["shared/safety.toml"]\nname = "inc"\n[environment]\nsubmarine = false\n'
        '[[apps.helm.behaviours]]\ntype = "constant_speed"\nname = "go"\nspeed = 1.0\n'
    )
    mission = load_mission(tmp_path / "m.toml")
    assert [b.name for b in mission.apps.helm.behaviours] == ["region", "go"]
    assert mission.apps.helm.variables == {"DEPLOY": True}


def test_include_cycles_and_missing_files_are_named(tmp_path):
    (tmp_path / "a.toml").write_text('include = ["b.toml"]\nname = "a"\n')
    (tmp_path / "b.toml").write_text('include = ["a.toml"]\n')
    with pytest.raises(MissionError, match="include cycle"):
        load_mission(tmp_path / "a.toml")
    (tmp_path / "c.toml").write_text('include = ["nowhere.toml"]\nname = "c"\n')
    with pytest.raises(MissionError, match="include 'nowhere.toml': no such file"):
        load_mission(tmp_path / "c.toml")


def test_a_bad_condition_is_one_line_naming_the_field_with_exit_2(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(
        'name = "bad"\n[[apps.helm.behaviours]]\ntype = "constant_speed"\nname = "go"\nspeed = 1.0\n'
        'condition = ["DEPLOY is true"]\n'
    )
    run = nearsub("launch", str(path))
    assert run.returncode == 2
    [line] = run.stderr.strip().splitlines()
    assert "condition" in line and "DEPLOY is true" in line


def test_poke_refuses_a_bad_assignment_with_exit_2():
    run = nearsub("poke", str(MISSIONS / "recovery.toml"), "PHASE")
    assert run.returncode == 2 and "expected NAME=VALUE" in run.stderr


POKE_MISSION = """
name = "pokes"
time_limit = 30.0
pause_at_step = 100
[start]
speed = 1.0
[environment]
submarine = false
[apps.helm.variables]
DIRECTION = "east"
[[apps.helm.behaviours]]
type = "constant_heading"
name = "east"
heading_deg = 0.0
condition = ["DIRECTION == east"]
[[apps.helm.behaviours]]
type = "constant_heading"
name = "north"
heading_deg = 90.0
condition = ["DIRECTION == north"]
"""


def test_nearsub_poke_switches_a_running_helm_and_the_log_replays_it(launches, community, tmp_path):

    path = tmp_path / "pokes.toml"
    path.write_text(POKE_MISSION)
    mission, process = poke_while_paused(launches, path, community, "DIRECTION=north")
    code, summary, err = finish(process)
    assert code == 0 and summary["outcome"] == "time_limit", err

    events = [r.value() for r in read_log(log_path(summary)).records if "/events/helm" in r.topic]
    [override] = [e for e in events if e["detail"].startswith("operator poke")]
    assert override["step"] == 100
    replay = [("helm", "poke", override["step"], Poke(**override["data"]["message"]))]
    reference = run_inprocess(
        build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps, operator=replay
    )
    logged = per_topic(log_path(summary))
    for leaf in ("state", "desired"):
        assert logged[f"remus100/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf
    headings = {m.step: m.psi_d for m in reference.topic("desired")}
    assert headings[95] == 0.0 and headings[100] == pytest.approx(math.pi / 2)


RECOVERY = MISSIONS / "recovery.toml"
STATION = (-3.44, 6.5)


def station_errors(result, mission, mode="RECOVERY:HOLD"):
    """Times [s] and distances [m] of the vehicle from the station point while the helm is in `mode`."""
    held = {m.step for m in result.topic("helm") if m.mode == mode}
    first, last = min(held), max(held)
    states = [m for m in result.topic("state") if first <= m.step <= last]
    t = np.array([m.t for m in states])
    error = np.array([math.hypot(m.x - STATION[0], m.y - STATION[1]) for m in states])
    return t, error


# In-process runs of the LF in the loop: 1-5 minutes on a busy two-core machine.
@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_station_keeping_holds_within_its_tolerance_for_120_s_beside_the_moving_hull():
    """U_sub = 1.5 m/s, the interaction on (increment mode), starting on the station point."""
    overrides = [f"start.x={STATION[0]}", f"start.y={STATION[1]}", "apps.helm.variables.PHASE='hold'", "time_limit=121"]
    mission = load_mission(RECOVERY, overrides)
    assert mission.environment.u_sub == 1.5 and mission.apps.sim.interaction == "increment"
    hold = next(b for b in mission.apps.helm.behaviours if b.type == "station_keep")
    result = run_mission(mission)
    forces = result.topic("forces")
    assert max(abs(m.applied_Y) for m in forces) > 0.0  # the interaction acts on the held station
    t, error = station_errors(result, mission)
    assert t[-1] - t[0] >= 120.0
    assert error.max() <= hold.tolerance


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_the_recovery_approaches_from_astern_holds_120_s_and_departs():
    mission = load_mission(RECOVERY)
    result = run_mission(mission)
    assert result.outcome == "completed", result.reason
    kinds = [e.kind for e in result.topic("events")]
    assert "collision" not in kinds and "close_call" not in kinds
    modes = [m.mode for m in result.topic("helm")]
    order = [mode for i, mode in enumerate(modes) if i == 0 or mode != modes[i - 1]]
    assert order == ["RECOVERY:APPROACH", "RECOVERY:HOLD", "RECOVERY:DEPART"]
    hold = next(b for b in mission.apps.helm.behaviours if b.type == "station_keep")
    t, error = station_errors(result, mission)
    assert t[-1] - t[0] >= 120.0
    # The approach hands over within its capture radius; on station within 20 s, then held.
    settled = t >= t[0] + 20.0
    assert error[settled].max() <= hold.tolerance
    first_hold = min(m.step for m in result.topic("helm") if m.mode == "RECOVERY:HOLD")
    astern = [m for m in result.topic("state") if m.step <= first_hold]
    assert all(m.x <= STATION[0] + hold.tolerance for m in astern)  # it came up from astern


def test_loiter_rounds_its_polygon_lap_after_lap_and_op_region_ends_the_mission_outside():
    square = [[30.0, -10.0], [30.0, 10.0], [10.0, 10.0], [10.0, -10.0]]
    mission = heading_mission(
        [spec("loiter", "round", polygon=square, speed=1.5, capture_radius=3.0)], time_limit=200.0
    )
    result = run_mission(mission)
    reached = [e for e in result.topic("events") if e.kind == "waypoint"]
    assert len(reached) > len(square)  # past the first lap
    assert reached[len(square)].detail.startswith("reached round point 1")
    region = [[-50.0, -50.0], [20.0, -50.0], [20.0, 50.0], [-50.0, 50.0]]
    fenced = heading_mission(
        [
            spec("constant_heading", "east", heading_deg=0.0),
            spec("constant_speed", "fast", speed=2.0),
            spec("op_region", "fence", polygon=region),
        ],
        time_limit=60.0,
    )
    result = run_mission(fenced)
    assert result.outcome == "error" and "fence: left the operating region" in result.reason
    assert 20.0 < result.topic("state")[-1].x < 21.0


def test_the_batch_engine_runs_the_helm_apps_own_arbitration():
    """A behaviour list through `run_batch` ends where the same mission run as apps ends."""
    from nearsub.common.analysis.batch import run_batch

    behaviours = [
        spec("constant_heading", "heading", heading_deg=30.0),
        spec("constant_speed", "speed", speed=1.2),
    ]
    starts = [(0.0, 40.0), (5.0, 35.0)]  # clear of the hull, which the batch always checks
    mission = heading_mission(behaviours)
    batch = run_batch(mission, np.array([[1.0, 0.0, 0.0, x, y, 0.0] for x, y in starts]), np.array([[100.0, 0.0]] * 2))
    for (x, y), final in zip(starts, batch.final, strict=True):
        alone = mission.model_copy(update={"start": mission.start.model_copy(update={"x": x, "y": y})})
        last = run_mission(alone).topic("state")[-1]
        assert np.allclose(final, [last.u, last.v, last.r, last.x, last.y, last.psi], rtol=0, atol=1e-9)
