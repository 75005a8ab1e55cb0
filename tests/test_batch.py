"""The batch engine agrees with the cores run one mission at a time (and so with the launcher,
which equals the in-process run bit for bit, tests/test_pipeline.py)."""

import json

import numpy as np
import pytest

from conftest import ALPHA
from nearsub.common.analysis.batch import OUTCOMES, run_batch
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission, mission_from_dict
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


@pytest.mark.parametrize("helm", ["legs", "behaviour list"])
def test_identical_uuvs_share_a_row_until_their_own_delta_tells_them_apart(helm, monkeypatch):
    """Three copies of each cell, each copy in its own field (a stand-in for posterior samples):
    flown together they share rows until delta is first asked, then split (state, pid memory and
    helm copied); each copy flown alone, where nothing is shared, gives the same bits."""
    from nearsub.common.analysis import batch as engine

    # Two cells in delta's window from the start, two drawn into it after 4-7 s, one that never asks.
    cells = [(-40.0, 5.9), (25.0, 6.0), (-34.63, 7.062), (38.28, 5.425), (0.0, 14.0)]
    surrogate = load_surrogate(None)
    mission = cell_mission(0.0, 0.0, None)
    if helm == "behaviour list":
        speed = {"type": "constant_speed", "name": "speed", "speed": 1.5}
        behaviours = [{"type": "constant_heading", "name": "heading", "heading_deg": 0.0}, speed]
        data = mission.model_dump(mode="json")
        data["apps"]["helm"] |= {"legs": [], "behaviours": behaviours}
        mission = mission_from_dict(data)
    starts = np.array([[1.5, 0.0, 0.0, x, y, 0.0] for x, y in cells])
    ends = np.array([[x + 1000.0, y] for x, y in cells])
    n, copies = len(cells), 3

    def field(X, uuvs):  # copy k sees the mean delta scaled by 1 + k / 10
        return surrogate.discrepancy(X, return_std=False)[0] * (1.0 + 0.1 * (uuvs // n))[:, None]

    rows = []
    real_step = engine.dynamics.step
    monkeypatch.setattr(engine.dynamics, "step", lambda x, *a, **k: rows.append(len(x)) or real_step(x, *a, **k))
    together = run_batch(mission, np.tile(starts, (copies, 1)), np.tile(ends, (copies, 1)), surrogate, delta=field)
    shared_rows = sum(rows)
    for k in range(copies):
        alone = run_batch(mission, starts, ends, surrogate, delta=lambda X, uuvs, k=k: field(X, uuvs + k * n))
        for name in ("outcome", "closest", "max_cross_track", "final", "steps"):
            np.testing.assert_array_equal(getattr(together, name)[k * n : (k + 1) * n], getattr(alone, name))
    final = together.final.reshape(copies, n, 6)
    assert not np.array_equal(final[1, :-1], final[0, :-1]) and np.array_equal(final[1, -1], final[0, -1])
    assert sum(rows) - shared_rows == together.steps.sum() > shared_rows  # alone: one row per UUV
