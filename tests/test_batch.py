"""The batch engine agrees with the cores run one mission at a time (and so with the launcher,
which equals the in-process run bit for bit, tests/test_pipeline.py)."""

import json

import numpy as np
import pytest

from conftest import ALPHA
from nearsub.common.analysis.batch import OUTCOMES, run_batch
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.surrogate.model import analytic_model, load_surrogate

CELLS = [(-40.0, 5.9), (-20.0, 5.7), (25.0, 6.0), (10.0, 8.0), (0.0, 5.3)]  # (x, y); the last one touches


def cell_mission(x, y, model_file, behaviour="waypoints", seconds=20):
    """One cell's mission. model_file None is the shipped model, in the default increment mode;
    the analytic fixture, which is no hydrodynamic model and has no free stream, runs in replace mode."""
    model = ["apps.sim.interaction=replace", f"surrogate.model={json.dumps(str(model_file))}"] if model_file else []
    return load_mission(
        ALPHA,
        [
            "environment.submarine=true",
            "environment.u_sub=1.5",
            "vehicle=sdv",
            "dt=0.1",
            f"time_limit={seconds}",
            f"start.x={x}",
            f"start.y={y}",
            "start.psi_deg=0",
            "start.speed=1.5",
            f"apps.helm.behaviour={behaviour}",
            f"apps.helm.legs=[{{points = [[{x + 1000.0}, {y}]], speed = 1.5, lead = 15.9, lead_to_start = true}}]",
            *model,
        ],
    )


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "analytic.npz"
    analytic_model(path=path)
    return path


@pytest.mark.parametrize("shipped", [False, True], ids=["analytic-replace", "shipped-increment"])
@pytest.mark.parametrize("behaviour", ["waypoints", "nuv_compensation"])
def test_batch_equals_single_missions(model_file, behaviour, shipped):
    model_file = None if shipped else model_file
    surrogate = load_surrogate(model_file)
    template = cell_mission(0.0, 0.0, model_file, behaviour)
    starts = np.array([[1.5, 0.0, 0.0, x, y, 0.0] for x, y in CELLS])
    ends = np.array([[x + 1000.0, y] for x, y in CELLS])
    batch = run_batch(template, starts, ends, surrogate)
    for i, (x, y) in enumerate(CELLS):
        single = run_mission(cell_mission(x, y, model_file, behaviour), surrogate)
        final = single.topic("state")[-1]
        np.testing.assert_allclose(
            batch.final[i], [final.u, final.v, final.r, final.x, final.y, final.psi], rtol=0, atol=1e-9
        )
        collided = single.outcome == "collision"
        assert (OUTCOMES[batch.outcome[i]] == "collision") == collided, (x, y)
        assert batch.steps[i] == single.steps
    assert OUTCOMES[batch.outcome[-1]] == "collision"  # 5.3 m < R_sub + D_uuv / 2 = 5.45 m


def test_inactive_cells_are_infeasible(model_file):
    template = cell_mission(0.0, 0.0, model_file, seconds=1)
    starts = np.array([[1.5, 0.0, 0.0, 0.0, 2.0, 0.0], [1.5, 0.0, 0.0, 0.0, 30.0, 0.0]])
    result = run_batch(
        template, starts, starts[:, 3:5] + [1000.0, 0.0], load_surrogate(model_file), np.array([False, True])
    )
    assert result.outcome_names() == ["infeasible", "safe"]
