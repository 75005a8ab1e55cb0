"""`nearsub train`: NMMF over the two physics fidelities, resumable, writing a multi-fidelity
model file the surrogate server loads (issue 6 item 5)."""

import argparse
import csv

import numpy as np
import pytest

from nearsub.common.learning.active import Campaign, CampaignSettings
from nearsub.common.surrogate.domain import sample_feasible
from nearsub.common.surrogate.model import Surrogate
from nearsub.common.surrogate.modelfile import MultiFidelitySurrogate, load_model
from nearsub.tools.train import interaction_problem, train_command

pytestmark = pytest.mark.timeout(300)


def args(tmp_path, **overrides):
    values = dict(
        budget=5,
        state=str(tmp_path / "campaign.json"),
        resume=False,
        restart=False,
        out=str(tmp_path / "model.npz"),
        seed=0,
        n_lf0=6,
        n_hf0=3,
        progress=False,
    )
    values.update(overrides)
    return argparse.Namespace(**values)


def test_a_killed_training_resumes_and_ships_a_multi_fidelity_model(tmp_path):
    problem = interaction_problem()
    settings = CampaignSettings(method="nmmf", hf_budget=5, selection="max-variance", seed=0, n_lf0=6, n_hf0=3)
    campaign = Campaign(problem, settings, path=tmp_path / "campaign.json")
    for _ in range(3):  # the initial designs and one NMMF step, then the process "dies"
        request = campaign.ask()
        campaign.tell(request.X, (problem.lf if request.fidelity == "lf" else problem.hf)(request.X))
    hf_before = campaign.data("hf")[0]
    assert train_command(args(tmp_path, resume=True)) == 0

    loaded = load_model(tmp_path / "model.npz")
    assert isinstance(loaded.model, MultiFidelitySurrogate)
    assert "NMMF" in loaded.provenance["method"] and "NOT RANS" in loaded.provenance["high_fidelity"]
    with open(tmp_path / "model-hf-samples.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 5 and set(rows[0]) == {
        "R_long",
        "R_lat",
        "u_kn",
        "psi_deg",
        "d_ratio",
        "ld_ratio",
        "X_p",
        "Y_p",
        "N_p",
    }
    X_hf = np.array(
        [[float(r[k]) for k in ("R_long", "R_lat", "u_kn", "psi_deg", "d_ratio", "ld_ratio")] for r in rows]
    )
    assert np.array_equal(X_hf[: len(hf_before)], hf_before)  # nothing repeated or lost

    surrogate = Surrogate(loaded)
    points = sample_feasible(20, seed=4)
    p = surrogate.predict(points)
    assert np.all(np.isfinite(p.mean)) and np.all(p.std >= 0)
    single = np.vstack([surrogate.predict(points[i : i + 1]).mean for i in range(len(points))])
    assert np.array_equal(single, p.mean)  # the multi-fidelity model keeps the row-wise bits


def test_train_refuses_to_overwrite_a_campaign(tmp_path):
    (tmp_path / "campaign.json").write_text("{}")
    assert train_command(args(tmp_path)) == 2
