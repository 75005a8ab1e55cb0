"""`nearsub train`: the LF-in-the-loop model from three training designs, resumable from its HF
store, writing a model file the surrogate server loads (common/surrogate/training.py)."""

import argparse
import csv
import time

import numpy as np
import pytest

from nearsub.common.hydro.low_fidelity import lf_coefficients
from nearsub.common.surrogate import training as tr
from nearsub.common.surrogate.domain import constraints_ok, in_domain, sample_feasible
from nearsub.common.surrogate.model import Surrogate
from nearsub.common.surrogate.modelfile import LFInLoopModel, load_model
from nearsub.common.surrogate.validation import HELD_OUT_POINTS, HELD_OUT_SEED, latin_hypercube_feasible
from nearsub.tools.commands.train import train_command

pytestmark = pytest.mark.timeout(300)


def fake_hf(x):
    """A cheap stand-in for the panel model: the LF, scaled, plus a smooth made-up residual."""
    y = 1.05 * lf_coefficients(x[None, :])[0] + 2e-5 * np.sin(3.0 * x[0]) * np.array([1.0, 3.0, 1.0])
    return y, 0.0


@pytest.fixture
def hf_calls(monkeypatch):
    calls = []

    def counted(x):
        calls.append(x.copy())
        return fake_hf(x)

    monkeypatch.setattr(tr, "timed_hf", counted)
    return calls


def args(tmp_path, **overrides):
    values = dict(
        envelope=None,
        samples=8,
        pool=None,
        compare=None,
        budgets=[25],
        designs=None,
        design="residual-us",
        budget=10,
        seed=1,
        n_seed=5,
        batch=3,
        workers=None,
        scheduler=None,
        state=str(tmp_path / "hf.csv"),
        restart=False,
        out=str(tmp_path / "model.npz"),
        data=None,
        progress=False,
    )
    values.update(overrides)
    return argparse.Namespace(**values)


def test_a_killed_training_resumes_without_repeating_a_run_and_ships_an_lf_in_the_loop_model(tmp_path, hf_calls):
    assert train_command(args(tmp_path, budget=7)) == 0  # the "killed" run: 7 of the 10 HF runs
    assert len(hf_calls) == 7
    assert train_command(args(tmp_path)) == 0
    assert len(hf_calls) == 10  # the first 7 came from the store

    loaded = load_model(tmp_path / "model.npz")
    assert isinstance(loaded.model, LFInLoopModel)
    prov = loaded.provenance
    assert prov["design"] == "residual-us" and "NOT RANS" in prov["high_fidelity"] and prov["hf_samples"] == 10
    with open(tmp_path / "model-hf-samples.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 10 and list(rows[0]) == ["R_long", "R_lat", "u_kn", "psi_deg", "d_ratio", "ld_ratio"] + [
        "X_p",
        "Y_p",
        "N_p",
    ]
    X = np.array([[float(r[k]) for k in list(rows[0])[:6]] for r in rows])
    assert np.array_equal(X, loaded.model.X)
    assert np.array_equal(X[:7], np.vstack(hf_calls[:7]))  # nothing repeated or lost

    surrogate = Surrogate(loaded)
    points = sample_feasible(20, seed=4)
    p = surrogate.predict(points)
    assert np.all(np.isfinite(p.mean)) and np.all(p.std >= 0)
    assert all(gp.n_restarts >= 10 for gp in loaded.model.gps)


def test_train_refuses_the_held_out_seed_and_bad_settings(tmp_path, capsys):
    assert train_command(args(tmp_path, seed=HELD_OUT_SEED)) == 2
    assert f"--seed {HELD_OUT_SEED}: reserved for the held-out" in capsys.readouterr().err
    assert train_command(args(tmp_path, n_seed=50)) == 2
    assert "--n-seed 50" in capsys.readouterr().err
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    assert train_command(args(tmp_path, state=str(tmp_path / "bad.csv"))) == 2
    assert "not an HF sample store" in capsys.readouterr().err


@pytest.mark.parametrize("design", [d for d in tr.DESIGNS if d != "envelope"])  # envelope: test_envelope_design.py
def test_every_design_stays_within_the_constraints_and_off_the_held_out_set(design, tmp_path):
    settings = tr.DesignSettings(design=design, budget=14, n_seed=6, batch=4)

    def run(X, done):
        for i, x in enumerate(X):
            done(i, *fake_hf(x))

    X, Y = tr.run_design(settings, tr.HFStore(None), run)
    assert X.shape == (14, 6) and np.all(np.isfinite(Y))
    assert in_domain(X).all() and constraints_ok(X).all()  # (4.4)-(4.7)
    assert len(np.unique(X, axis=0)) == len(X)
    assert tr.held_out_overlap(X) == 0
    assert np.array_equal(X[:6], tr.sobol_design(6))  # seeded by the space-filling design


def test_sobol_prefixes_are_nested_and_the_held_out_set_is_detected():
    assert np.array_equal(tr.sobol_design(30)[:10], tr.sobol_design(10))
    held = latin_hypercube_feasible(HELD_OUT_POINTS, HELD_OUT_SEED)
    assert tr.held_out_overlap(np.vstack([tr.sobol_design(5), held[:3]])) == 3


def test_hf_runs_on_a_local_cluster_match_this_process(tmp_path):
    X = tr.sobol_design(2)
    with tr.hf_runner() as run:
        here = tr.evaluate_hf(X, tr.HFStore(tmp_path / "a.csv"), run)
    started = time.perf_counter()
    with tr.hf_runner(workers=2) as run:
        there = tr.evaluate_hf(X, tr.HFStore(tmp_path / "b.csv"), run)
    assert time.perf_counter() - started < 240
    assert np.array_equal(here, there)
    assert np.array_equal(tr.HFStore(tmp_path / "b.csv").get(X[1]), there[1])  # stored as it finished
