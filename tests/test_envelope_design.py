"""The envelope design (`nearsub train --design envelope`): its acquisition's algebra against a
brute-force conditioning, the envelope specs, pool mode and the provenance of the files a model
was trained from (common/learning/envelope_design.py, common/analysis/envelope_design.py)."""

import hashlib

import numpy as np
import pytest
from test_train import args as train_args

from nearsub.common.analysis import envelope_design as ed
from nearsub.common.learning.envelope_design import (
    condition_on_mean,
    envelope_picks,
    explained_shares,
    posterior_variance,
)
from nearsub.common.learning.gp import MultiOutputGP
from nearsub.common.surrogate import training as tr
from nearsub.common.surrogate.domain import constraints_ok, in_domain
from nearsub.common.surrogate.modelfile import load_model
from nearsub.tools.commands.train import command_line, train_command

pytestmark = pytest.mark.timeout(600)


def small_gp(seed=0):
    rng = np.random.default_rng(seed)
    X = rng.random((15, 2))
    Y = np.column_stack([np.sin(4 * X[:, 0]) + X[:, 1], np.cos(3 * X[:, 1]) * X[:, 0]])
    return MultiOutputGP(bounds=[[0, 1], [0, 1]], n_restarts=2, seed=seed).fit(X, Y), rng


def test_the_explained_share_is_the_variance_that_conditioning_on_the_candidate_removes():
    model, rng = small_gp()
    candidates, targets = rng.random((6, 2)), rng.random((9, 2))
    cell = np.array([0, 0, 0, 1, 1, 2, 2, 2, 2])
    rho = explained_shares(model, candidates, targets, cell, 4)
    assert rho.shape == (6, 4) and np.all(rho[:, 3] == 0.0)  # cell 3 has no target point
    for i, x in enumerate(candidates):
        after = condition_on_mean(model, x[None, :])
        brute = np.zeros(3)
        for gp, gp_after in zip(model.gps, after.gps, strict=True):
            before_var, after_var = posterior_variance(gp, targets), posterior_variance(gp_after, targets)
            for c in range(3):
                brute[c] += 1 - after_var[cell == c].sum() / before_var[cell == c].sum()
        np.testing.assert_allclose(rho[i, :3], brute / 2, rtol=1e-3)  # the look-ahead fit may add its own jitter


def test_greedy_picks_aim_at_the_heavy_cells_and_never_repeat():
    model, rng = small_gp(1)
    targets = np.vstack([np.full((4, 2), 0.9) + 0.01 * rng.random((4, 2)), np.full((4, 2), 0.1)])
    cell = np.repeat([0, 1], 4)
    candidates = np.array([[0.1, 0.1], [0.9, 0.9], [0.5, 0.5], [0.88, 0.9]])
    picks, values = envelope_picks(model, candidates, targets, cell, np.array([1.0, 0.0]), 3)
    assert picks[0] in (1, 3) and len(set(picks)) == 3  # only cell 0 weighs
    assert values[0] >= values[1] >= values[2] >= 0.0


def test_an_envelope_spec_is_read_and_a_bad_one_named():
    spec = ed.parse_spec("vehicle=small,behaviour=nuv_compensation,grid=8x4,r_lat=0.055:0.07,sea_state=5")
    assert (spec.vehicle, spec.behaviour, spec.grid, spec.r_lat, spec.sea_state) == (
        "remus100",
        "nuv_compensation",
        (8, 4),
        (0.055, 0.07),
        5,
    )
    assert ed.parse_spec("vehicle=sdv").grid == ed.DEFAULT_SPEC_GRID
    for bad, named in (("vehicle=submarine", "vehicle"), ("colour=red", "colour"), ("sea_state=9", "sea_state")):
        with pytest.raises(ValueError, match=named):
            ed.parse_spec(bad)


def pool(n=40):
    X = tr.sobol_design(n)
    return X, 1.02 * np.nan_to_num(tr.hydro_lf.lf_coefficients(X)) + 1e-5 * np.sin(5 * X[:, [0]])


def test_pool_mode_picks_only_pool_rows_and_refuses_any_other_hf_run():
    X, Y = pool()
    settings = tr.DesignSettings(design="residual-us", budget=18, n_seed=6, batch=4, stops=(12,))
    picked, values = tr.run_design(settings, tr.pool_store(X, Y), tr.pool_runner, candidates=tr.pool_candidates(X))
    rows = [int(np.flatnonzero(np.all(X == x, axis=1))[0]) for x in picked]
    assert rows[:6] == list(range(6)) and len(set(rows)) == 18  # seeded by the pool's Sobol prefix
    np.testing.assert_array_equal(values, Y[rows])
    with pytest.raises(tr.NotInPoolError):
        tr.run_design(tr.DesignSettings(design="sobol", budget=41), tr.pool_store(X, Y), tr.pool_runner)


def test_the_envelope_design_aims_at_doubtful_cells_within_the_constraints():
    X, Y = pool(60)
    spec = ed.parse_spec("vehicle=sdv,grid=8x4,r_lat=0.055:0.075,duration=30")
    rounds = []
    settings = tr.DesignSettings(design="envelope", budget=16, n_seed=10, batch=3)
    acquire = ed.acquisition([spec], samples=4, log=rounds)
    picked, _ = tr.run_design(
        settings, tr.pool_store(X, Y), tr.pool_runner, candidates=tr.pool_candidates(X), acquire=acquire
    )
    assert picked.shape == (16, 6) and len(np.unique(picked, axis=0)) == 16
    assert in_domain(picked).all() and constraints_ok(picked).all()
    assert [r["hf_samples"] for r in rounds] == [10, 13]
    assert all(r["values"][0] > 0.0 for r in rounds)  # some trajectory asks delta, so a pick explains something
    with pytest.raises(ValueError, match="--envelope"):
        tr.run_design(settings, tr.pool_store(X, Y), tr.pool_runner, candidates=tr.pool_candidates(X))


def test_a_model_names_its_files_relative_to_the_working_directory_or_by_name_and_hash(tmp_path, monkeypatch):
    X, Y = pool(12)
    samples = tmp_path / "pool.csv"
    tr.write_samples(samples, X, Y)
    work = tmp_path / "work"
    work.mkdir()
    (work / "runs").mkdir()
    tr.write_samples(work / "runs" / "hf.csv", X, Y)
    monkeypatch.chdir(work)
    assert tr.file_reference(work / "runs" / "hf.csv")["file"] == "runs/hf.csv"
    outside = tr.file_reference(samples)  # a temporary folder's file: its name and hash only
    assert outside == {"file": "pool.csv", "sha256": hashlib.sha256(samples.read_bytes()).hexdigest()}
    settings = train_args(tmp_path, design="sobol", state=str(tmp_path / "hf-store.csv"), out="model.npz")
    settings.pool = [str(samples)]
    assert train_command(settings) == 0
    provenance = load_model(work / "model.npz").provenance
    assert provenance["pool"] == [outside] and "hf_store" not in provenance
    assert str(tmp_path) not in repr(provenance)
    argv = ["/usr/bin/nearsub", "train", "--state", str(tmp_path / "hf.csv"), f"--out={work / 'runs' / 'm.npz'}"]
    monkeypatch.setattr("sys.argv", argv)
    assert command_line("") == "nearsub train --state hf.csv --out=runs/m.npz"
