"""The sim and helm with the surrogate's interaction forces (thesis (5.20), chapter 6)."""

import json
import os
import signal
from contextlib import contextmanager

import numpy as np
import pytest

from conftest import ALPHA
from helpers import command_line, finish, log_path, per_topic, wait_registered
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.physics.dynamics import Interaction, body_forces
from nearsub.common.physics.vehicles import SDV
from nearsub.common.runtime.messages import encode
from nearsub.common.surrogate.interaction import blend_weight, interaction_at
from nearsub.common.surrogate.model import analytic_model, load_surrogate

pytestmark = pytest.mark.timeout(180)

# An SDV holding station beside the submarine's afterbody, 5.9 m off its axis (R_lat = 0.066,
# inside its feasible window of 5.55-6.24 m set by constraints (4.4) and (4.5)).
BESIDE = [
    "environment.submarine=true",
    "environment.u_sub=1.5",
    "vehicle=sdv",
    "start.x=-30",
    "start.y=5.9",
    "start.psi_deg=0",
    "start.speed=1.5",
    "apps.helm.legs=[{points = [[60.0, 5.9]], speed = 1.5, lead = 15.9, lead_to_start = true}]",
    "time_limit=20",
    "apps.sim.interaction=replace",  # the analytic fixture is no hydrodynamic model: no free stream
]


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "analytic.npz"
    analytic_model(path=path)
    return path


def test_no_force_jump_across_the_domain_boundary(model_file):
    """Sweep the SDV outwards across its lateral limit, constraint (4.5) at y = 6.24 m (2 D_uuv off
    the hull): the blend weight goes from 1 to 0 and the total force changes smoothly, with no step
    larger than the blend's slope allows."""
    surrogate = load_surrogate(model_file)
    y = np.linspace(5.8, 6.8, 1001)  # 1 mm apart
    states = np.column_stack(
        [np.full_like(y, 1.5), np.zeros_like(y), np.zeros_like(y), np.full_like(y, -30.0), y, np.zeros_like(y)]
    )
    seen = interaction_at(surrogate, states, SDV, 1025.0, "replace")
    total = body_forces(states, np.zeros((len(y), 2)), SDV, seen.interaction)
    weight = seen.interaction.weight
    assert weight[0] == 1.0 and weight[-1] == 0.0 and np.all(np.diff(weight) <= 0)
    band = (weight > 0) & (weight < 1)
    assert band.sum() > 40  # the blend spreads over about 5 cm
    # Inside the band the force may move by (weight step) x (surrogate - (5.10) flow terms); away
    # from it only by the smooth change of the forces themselves. Nothing more: no jump.
    plain = body_forces(states, np.zeros((len(y), 2)), SDV)
    full = Interaction(seen.interaction.forces, np.ones_like(weight))
    gap = np.abs(body_forces(states, np.zeros((len(y), 2)), SDV, full) - plain)  # surrogate - flow terms
    steps = np.abs(np.diff(total, axis=0))
    dw = np.abs(np.diff(weight))[:, None]
    smooth = np.abs(np.diff(plain, axis=0)) + np.abs(np.diff(seen.interaction.forces, axis=0))
    assert np.all(steps <= dw * gap[1:] + smooth + 1e-9)
    assert dw.max() <= 1.5 * (y[1] - y[0]) / (band.sum() * (y[1] - y[0])) * 1.1  # smoothstep's slope


def test_blend_weight_is_zero_outside_bounds_and_constraints():
    inside = np.array([0.0, 0.066, 3.0, 0.0, 20.0, 8.0])  # feasible: (4.4) 0.032, (4.5) 0.034
    assert blend_weight(inside) == 1.0
    for column, value in ((0, 0.75), (1, 0.12), (3, 2.5), (2, 1.0)):
        outside = inside.copy()
        outside[column] = value
        assert blend_weight(outside) == 0.0
    infeasible = np.array([0.0, 0.059, 3.0, 0.0, 5.0, 8.0])  # (4.4): the hulls would overlap
    assert blend_weight(infeasible) == 0.0


def test_a_hull_outside_the_trained_ratios_is_reported_and_clipped(model_file):
    from nearsub.common.physics.vehicles import REMUS100
    from nearsub.common.surrogate.interaction import geometry_outside

    assert geometry_outside(SDV) is None
    assert "d_ratio = 54.3" in geometry_outside(REMUS100)
    surrogate = load_surrogate(model_file)
    state = np.array([1.5, 0.0, 0.0, -30.0, 5.45, 0.0])  # in its 0.26 m window beside the hull
    seen = interaction_at(surrogate, state, REMUS100, 1025.0, "replace")
    assert seen.interaction.weight == 1.0 and not seen.in_domain[0]  # answered at d_ratio 50, flagged


def test_sim_publishes_interaction_forces_every_step(model_file):
    mission = load_mission(ALPHA, BESIDE)
    result = run_mission(mission, load_surrogate(model_file))
    forces = result.topic("forces")
    assert [f.step for f in forces] == list(range(result.steps))
    assert all(f.in_domain and f.constraints_ok and f.weight == 1.0 for f in forces[:50])
    assert abs(forces[0].Y_s) > 0


def test_compensation_offsets_the_desired_heading(model_file):
    mission = load_mission(ALPHA, BESIDE + ["apps.helm.behaviour=nuv_compensation"])
    result = run_mission(mission, load_surrogate(model_file))
    progress = result.topic("helm")
    assert all(p.behaviour == "nuv_compensation" for p in progress)
    assert any(abs(p.delta_psi) > 1e-4 for p in progress)
    assert all(p.n_s != 0.0 for p in progress[:5])


def test_multi_process_with_the_surrogate_server_equals_in_process(launches, community, model_file):
    settings = BESIDE + [f"surrogate.model={json.dumps(str(model_file))}", "apps.helm.behaviour=nuv_compensation"]
    code, summary, err = launches.run(ALPHA, *sum((["--set", s] for s in settings), []), "--set", f"name={community}")
    assert code == 0, err
    reference = run_mission(load_mission(ALPHA, settings + [f"name={community}"]), load_surrogate(model_file))
    logged = per_topic(log_path(summary))
    for leaf in ("state", "desired", "input", "forces", "helm"):
        assert logged[f"sdv/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf


def test_a_lost_surrogate_server_stops_the_mission_naming_it(launches, community, model_file):
    settings = BESIDE + [f"surrogate.model={json.dumps(str(model_file))}", "time_limit=600"]
    process = launches.start(
        ALPHA, *sum((["--set", s] for s in settings), []), "--set", f"name={community}", "--warp", "5"
    )
    wait_registered(community)
    with hung_server(launches):  # only the query timeout can notice
        code, summary, err = finish(process)
    assert code == 1
    assert summary["outcome"] == "error" and "surrogate server" in summary["reason"]


def test_a_sim_with_the_surrogate_in_process_needs_no_server(launches, community, model_file):
    """apps.sim.surrogate = "in_process": the sim loads the model itself, so a hung surrogate
    server (which would end a "server" mission, as above) does not stop it, and the forces are
    those of the in-process run."""
    settings = BESIDE + [f"surrogate.model={json.dumps(str(model_file))}", "apps.sim.surrogate=in_process"]
    settings += ["time_limit=20"]
    process = launches.start(
        ALPHA, *sum((["--set", s] for s in settings), []), "--set", f"name={community}", "--warp", "5"
    )
    wait_registered(community)
    with hung_server(launches):
        code, summary, err = finish(process)
    assert code == 0 and summary["outcome"] == "time_limit", err
    reference = run_mission(load_mission(ALPHA, settings + [f"name={community}"]), load_surrogate(model_file))
    assert per_topic(log_path(summary))["sdv/forces"] == [encode(m) for m in reference.topic("forces")]


@contextmanager
def hung_server(launches):
    """The running mission's surrogate server stopped (SIGSTOP: hung, not dead), then killed."""
    pids = [int(p) for p in os.listdir("/proc") if p.isdigit() and _is_server(p, launches.log_dir)]
    assert len(pids) == 1
    os.kill(pids[0], signal.SIGSTOP)
    try:
        yield
    finally:
        try:
            os.kill(pids[0], signal.SIGKILL)
        except ProcessLookupError:
            pass  # the launcher's stop ladder already did


def _is_server(pid: str, log_dir) -> bool:
    try:
        argv = command_line(pid)
    except OSError:
        return False
    return "nearsub.apps.surrogate" in argv and any(str(log_dir) in a for a in argv)


def test_compensated_heading_is_what_the_helm_publishes(model_file):
    mission = load_mission(ALPHA, BESIDE + ["apps.helm.behaviour=nuv_compensation"])
    result = run_mission(mission, load_surrogate(model_file))
    for desired, progress in zip(result.topic("desired"), result.topic("helm"), strict=True):
        assert desired.psi_d == progress.psi_d
        assert (progress.delta_psi != 0.0) == (progress.n_s != 0.0)  # zero outside the domain only


def test_a_hull_outside_the_shape_constraints_is_reported_as_getting_no_surrogate_share():
    """The NPS AUV II (L/D 5.31 at D_sub/D_uuv 24.7) fails (4.6), "not too short": no surrogate
    share (the LF increment alone in increment mode)."""
    from nearsub.common.physics.vehicles import NPS_AUV_II
    from nearsub.common.surrogate.interaction import geometry_outside

    reason = geometry_outside(NPS_AUV_II)
    assert reason is not None and "(4.6)" in reason and "zero everywhere" in reason and "LF increment" in reason
    assert geometry_outside(SDV) is None


@pytest.mark.parametrize("vehicle", ["sdv", "remus100"])  # hull ratios inside table 4.2, and clipped
def test_each_row_of_a_batch_has_the_bits_of_the_state_asked_alone(vehicle):
    """The single-row shortcuts (constraint values reused between the weights, x_c and the flags,
    conversions without broadcast copies) keep the row-by-row arithmetic: a batch's row and the same
    state asked alone agree bit for bit in all but the std (a BLAS product, `gp._Predictor.rows`)."""
    from nearsub.common.physics.vehicles import get_vehicle

    surrogate, uuv = load_surrogate(None), get_vehicle(vehicle)
    rng = np.random.default_rng(3)
    n = 40
    states = np.column_stack(
        [
            rng.uniform(1.0, 2.5, n),
            np.zeros(n),
            np.zeros(n),
            rng.uniform(-80.0, 80.0, n),  # inside and beyond table 4.2's R_long
            rng.uniform(4.5, 12.0, n) * rng.choice([-1.0, 1.0], n),  # both sides, in and beyond (4.5)
            rng.uniform(-0.1, 0.1, n),
        ]
    )
    batch = interaction_at(surrogate, states, uuv, 1025.0, "increment")
    for i, state in enumerate(states):
        alone = interaction_at(surrogate, state, uuv, 1025.0, "increment")
        for name in ("forces", "applied", "model", "lf", "delta_free", "delta_weight", "outside_mask", "lf_held"):
            np.testing.assert_array_equal(getattr(alone, name)[0], getattr(batch, name)[i], err_msg=name)
