"""The "increment" interaction mode (docs/design.md, "Physics decisions"): the surrogate's prediction minus the
high-fidelity model's free stream for the lone UUV (common/free_stream.py, nearsub/data/
surrogate-free-stream.npz), added to the vehicle's own (5.11) forces."""

import json
from dataclasses import asdict

import numpy as np
import pytest
from test_interaction import BESIDE

from conftest import ALPHA, ROOT
from helpers import log_path, per_topic
from nearsub.common.hydro import high_fidelity as hydro_hf
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.physics.vehicles import REMUS100, SDV
from nearsub.common.runtime.messages import encode
from nearsub.common.surrogate import domain
from nearsub.common.surrogate import free_stream as fs
from nearsub.common.surrogate.interaction import GEOMETRY, IncrementError, interaction_at
from nearsub.common.surrogate.model import analytic_model, load_surrogate
from nearsub.tools import free_stream as free_stream_tool

pytestmark = pytest.mark.timeout(180)

RHO = 1025.0  # sea water (docs/design.md, "Frames, units and signs")
# The shipped table against hf_free_stream (MEDIUM panels) off its grid, in X', Y', N': about twice
# the largest errors its build measured at 300 points (7.8e-6, 9.3e-7, 2.4e-7; free_stream.GRID).
TOLERANCE = np.array([1.5e-5, 2e-6, 5e-7])


@pytest.fixture(scope="module")
def shipped():
    return load_surrogate()


@pytest.fixture(scope="module")
def table():
    return fs.load_table(fs.default_table_path())


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "analytic.npz"
    analytic_model(path=path)
    return path


def clipped_inputs(states, vehicle):
    raw, mirror = domain.to_inputs(
        states[:, 3], states[:, 4], states[:, 0], states[:, 5], vehicle.length, vehicle.diameter
    )
    raw[:, GEOMETRY] = np.clip(raw[:, GEOMETRY], domain.BOUNDS[GEOMETRY, 0], domain.BOUNDS[GEOMETRY, 1])
    return raw, mirror


def test_shipped_table_is_the_shipped_models_and_matches_hf_free_stream_off_grid(shipped, table):
    assert table.surrogate_model_id == shipped.model_id
    provenance = table.provenance
    assert provenance["panels"] == asdict(hydro_hf.MEDIUM) and provenance["created_utc"]
    assert [provenance["grid"][name][2] for name in fs.AXIS_NAMES] == list(fs.GRID)
    # L/D in the middle of grid cells (the farthest from the nodes), plus the SDV at 1.75 m/s.
    rows = fs.check_inputs(table.axes, 5, seed=7)
    sdv, _ = clipped_inputs(np.array([[1.75, 0.0, 0.0, -30.0, 5.9, np.radians(0.7)]]), SDV)
    rows = np.vstack([rows, sdv])
    error = np.abs(table.coefficients(rows) - hydro_hf.hf_free_stream(rows))
    assert np.all(error <= TOLERANCE), error


def test_increment_is_the_prediction_minus_the_free_stream_at_the_same_clipped_inputs(model_file, table):
    """A model without the LF in the loop (here the analytic fixture, given the shipped table), on
    both sides of the submarine (mirrored heading, Y and N), both signs of psi, and a hull outside
    the trained ratios (REMUS 100, D_sub/D_uuv = 54 clipped to 50): the forces the dynamics add are
    the replace mode's minus the free stream of the same inputs, and that free stream is the lone
    UUV's, evaluated directly."""
    model = load_surrogate(model_file)
    for vehicle, y, u in ((SDV, 5.9, 1.75), (REMUS100, 5.45, 1.5)):
        states = np.array(
            [
                [u, 0.0, 0.0, x, side * y, side * np.radians(psi)]
                for x in (-30.0, 10.0)
                for side in (1, -1)
                for psi in (1.5, -0.8)
            ]
        )
        replace = interaction_at(model, states, vehicle, RHO, "replace")
        increment = interaction_at(model, states, vehicle, RHO, "increment", free_stream=table)
        inputs, mirror = clipped_inputs(states, vehicle)
        free = domain.to_forces(table.coefficients(inputs), mirror, states[:, 0], vehicle.length, RHO)
        np.testing.assert_allclose(increment.forces, replace.forces - free, rtol=1e-12, atol=1e-9)
        np.testing.assert_array_equal(increment.interaction.forces, increment.forces)
        np.testing.assert_array_equal(increment.interaction.weight, replace.interaction.weight)
        np.testing.assert_array_equal(increment.std, replace.std)
        assert increment.interaction.mode == "increment" and np.all(replace.interaction.weight > 0)
        direct = domain.to_forces(hydro_hf.hf_free_stream(inputs), mirror, states[:, 0], vehicle.length, RHO)
        scale = domain.to_forces(np.tile(TOLERANCE, (len(states), 1)), 1.0, states[:, 0], vehicle.length, RHO)
        assert np.all(np.abs(replace.forces - increment.forces - direct) <= scale)
        assert np.all(np.abs(direct[:, 2]) > 0.0) and np.all(np.sign(direct[:, 2]) == np.sign(states[:, 5]))


def test_increment_at_the_outer_lateral_edge_is_much_smaller_than_the_total(shipped, table):
    """At the outer edge of the SDV's lateral window (constraint (4.5), y = 6.24 m; here 6.2 m, where
    the blend weight is still 0.9) beside the parallel midbody, most of the total force is the
    UUV's own drag and Munk moment: the increment leaves a small part of it. In the sim (shipped GP,
    the panel-trained increment: the viscous correction adds RANS's small yaw moment beside the
    midbody, which is not the free stream's) and in the high-fidelity model itself."""
    psi = np.radians(1.5)
    states = np.array([[1.75, 0.0, 0.0, x, 6.2, psi] for x in (-15.0, 0.0, 15.0)])
    total = interaction_at(shipped, states, SDV, RHO, "replace").forces
    increment = interaction_at(shipped, states, SDV, RHO, "increment", viscous=False).forces
    assert np.all(np.abs(increment[:, 0]) < 0.3 * np.abs(total[:, 0]))  # surge: the drag is gone
    assert abs(increment[1, 2]) < 0.2 * abs(total[1, 2])  # yaw abreast the CB: the Munk moment is gone
    # The high-fidelity model at R_long = 0 on the edge (table 4.2 with (4.5)): the interaction is a
    # few per cent of the lone UUV's drag and Munk moment (it decays with
    # the clearance).
    inputs, _ = clipped_inputs(states[1:2], SDV)
    hf_total = hydro_hf.hf_coefficients(inputs)
    hf_increment = hf_total - table.coefficients(inputs)
    assert abs(hf_increment[0, 0]) < 0.1 * abs(hf_total[0, 0])
    assert abs(hf_increment[0, 2]) < 0.1 * abs(hf_total[0, 2])


def test_a_model_without_its_table_is_refused_naming_the_mission_field_and_the_file(model_file, tmp_path):
    surrogate = load_surrogate(model_file)
    state = np.array([1.75, 0.0, 0.0, -30.0, 5.9, 0.0])
    interaction_at(surrogate, state, SDV, RHO, "replace")  # the other modes do not need a table
    with pytest.raises(IncrementError) as error:
        interaction_at(surrogate, state, SDV, RHO, "increment")
    message = str(error.value)
    assert "apps.sim.interaction" in message and str(model_file) in message and surrogate.model_id in message
    mission = load_mission(
        ROOT / "missions" / "overtake_stern_standard.toml",
        ["apps.sim.interaction=increment", f'surrogate.model="{model_file}"'],
    )
    with pytest.raises(IncrementError, match="apps.sim.interaction"):
        run_mission(mission)  # at step 0, before the vehicle moves
    # The table tool refuses a model that was not trained on the panel model (this one is analytic).
    assert free_stream_tool.main([str(model_file), "--out", str(tmp_path / "t.npz")]) == 2
    assert not (tmp_path / "t.npz").exists()


def test_a_table_next_to_the_model_file_is_used_and_round_trips(model_file):
    surrogate = load_surrogate(model_file)
    table = fs.build_table(hydro_hf.COARSE, (4, 5, 4), surrogate_model_id=surrogate.model_id, check_points=20)
    check = table.provenance["check"]
    assert np.all(np.array(check["max_abs_error"]) < 0.05 * np.array(check["max_abs_value"]))
    path = fs.save_table(fs.table_path_for(model_file), table)
    assert path.name == "analytic-free-stream.npz"
    loaded = fs.load_table(path)
    rows = fs.check_inputs(table.axes, 10)
    np.testing.assert_array_equal(loaded.coefficients(rows), table.coefficients(rows))
    assert loaded.provenance["panels"] == asdict(hydro_hf.COARSE)
    states = np.array([[1.75, 0.0, 0.0, -30.0, 5.9, np.radians(1.0)], [1.75, 0.0, 0.0, 10.0, -5.9, 0.0]])
    increment = interaction_at(surrogate, states, SDV, RHO, "increment")
    replace = interaction_at(surrogate, states, SDV, RHO, "replace")
    inputs, mirror = clipped_inputs(states, SDV)
    free = domain.to_forces(loaded.coefficients(inputs), mirror, states[:, 0], SDV.length, RHO)
    np.testing.assert_allclose(increment.forces, replace.forces - free, rtol=1e-12, atol=1e-9)
    path.unlink()
    with pytest.raises(IncrementError):  # another model object: looked up again, and gone
        interaction_at(load_surrogate(model_file), states, SDV, RHO, "increment")


def test_queries_outside_the_grid_are_clamped_and_finite(table):
    rows = np.array(
        [
            [0.0, 0.07, 0.0, 0.0, 20.0, 8.0],  # u = 0: Re = 0, log10 = -inf
            [0.0, 0.07, 3.0, 179.0, 20.0, 8.0],  # heading far outside +/-2 deg
            [0.0, 0.07, np.nan, 0.0, 20.0, 8.0],
        ]
    )
    values = table.coefficients(rows)
    assert np.all(np.isfinite(values))
    np.testing.assert_array_equal(values[1], table.coefficients([[0.0, 0.07, 3.0, 2.0, 20.0, 8.0]])[0])


# test_interaction's SDV holding station beside the afterbody, in its lateral window, in increment mode.
INCREMENT = [*BESIDE, "time_limit=10", "apps.sim.interaction=increment"]


@pytest.mark.parametrize("where", ["server", "in_process"])
def test_multi_process_increment_equals_in_process(launches, community, where):
    """The sim app asks the surrogate server which model it serves, and finds the shipped table;
    or, with apps.sim.surrogate = "in_process", loads that model itself: the same forces either way."""
    settings = [*INCREMENT, f"apps.sim.surrogate={where}"]
    code, summary, err = launches.run(ALPHA, *sum((["--set", s] for s in settings), []), "--set", f"name={community}")
    assert summary.get("outcome") in ("time_limit", "collision"), err  # the run ends by itself, not by an error
    reference = run_mission(load_mission(ALPHA, settings + [f"name={community}"]), load_surrogate())
    logged = per_topic(log_path(summary))
    for leaf in ("state", "forces"):
        assert logged[f"sdv/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf


def test_multi_process_increment_without_a_table_ends_naming_the_field(launches, community, model_file):
    settings = INCREMENT + [f"surrogate.model={json.dumps(str(model_file))}"]
    code, summary, err = launches.run(ALPHA, *sum((["--set", s] for s in settings), []), "--set", f"name={community}")
    assert code == 1
    assert summary["outcome"] == "error" and "apps.sim.interaction" in summary["reason"], summary
