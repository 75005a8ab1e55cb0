"""`nearsub al-bench` files: written, read back, summarised again (--from-files), as markdown."""

import subprocess
import sys

import numpy as np
import pytest

from nearsub.common.analysis.albench import summarise
from nearsub.tools.commands.al_bench import markdown_tables, read_outputs, write_outputs


def _result(rng):
    methods, counts, repeats = ["nmmf", "myopic", "hf-us"], list(range(5, 11)), 4
    return {
        "problem": "park",
        "outputs": ["y"],
        "methods": methods,
        "repeats": repeats,
        "hf_samples": 10,
        "seed": 0,
        "jobs": 1,
        "settings": {},
        "test_points": 10,
        "n_hf": counts,
        "mape": {m: rng.uniform(0.1, 2.0, (repeats, len(counts), 1)) for m in methods},
        "reference": {"counts": [10], "mape": {m: rng.uniform(0.1, 2.0, (repeats, 1, 1)) for m in methods}},
        "wall_seconds": 1.0,
        "task_seconds_per_method": {m: 0.1 for m in methods},
    }


def test_files_read_back_to_the_same_result_and_summary(tmp_path):
    result = _result(np.random.default_rng(3))
    summary = summarise(result)
    write_outputs(result, summary, tmp_path)
    back = read_outputs("park", tmp_path)
    for key in ("mape", "reference"):
        mapes = back[key] if key == "mape" else back[key]["mape"]
        want = result[key] if key == "mape" else result[key]["mape"]
        assert all(np.array_equal(mapes[m], want[m]) for m in result["methods"])
    assert summarise(back) == summary
    pairs = summary["outputs"]["y"]["pairs"]
    a, b = result["mape"]["nmmf"][:, :, 0], result["mape"]["myopic"][:, :, 0]
    assert pairs["nmmf<myopic"] == np.mean(a < b, axis=0).tolist()
    assert set(pairs) == {"nmmf<myopic", "nmmf<hf-us", "myopic<hf-us"}
    table = markdown_tables(back, summary)
    med = summary["outputs"]["y"]["reference_gp"]["stats"]["nmmf"]["median"][0]
    assert "| 10, reference GP | " + f"{med:.3g} (" in table and "nmmf < myopic" in table


def test_from_files_without_files_is_one_line_and_exit_2(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "nearsub", "al-bench", "park", "--from-files", "-o", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.startswith("nearsub al-bench: --from-files: no ") and len(done.stderr.splitlines()) == 1


def _csv_rows(path):
    return path.read_text().splitlines()


@pytest.mark.timeout(600)  # CPU-bound, three short runs: the timeout catches a hang
def test_resumed_run_equals_one_run_row_for_row(tmp_path):
    """Repeats 0-1, then a run resumed to 4 repeats, write the same files, row for row, as one
    run of repeats 0-3: each repeat depends only on its seed."""
    from nearsub.common.analysis.albench import run_benchmark
    from nearsub.common.learning.reference_gp import missing

    kw = dict(
        hf_samples=7,
        methods=("nmmf-exact-lf", "hf-us"),
        test_points=200,
        reference_counts=() if missing() else (7,),
        n_lookahead=2,
        candidates_per_dim=100,
        n_polish=1,
        n_restarts=1,
    )
    parts, whole = tmp_path / "parts", tmp_path / "whole"
    seen = []
    first = run_benchmark("park", repeats=2, on_checkpoint=lambda r: seen.append(r), **kw)
    assert [r["repeats"] for r in seen] == [1, 2]  # written as each repeat completes
    assert all(np.array_equal(seen[-1]["mape"][m], first["mape"][m]) for m in first["methods"])
    write_outputs(first, summarise(first), parts)
    resumed = run_benchmark("park", repeats=4, jobs=2, previous=read_outputs("park", parts), **kw)
    assert resumed["repeats"] == 4 and [r["repeats"] for r in resumed["runs"]] == [[0, 2], [2, 4]]
    write_outputs(resumed, summarise(resumed), parts)
    once = run_benchmark("park", repeats=4, jobs=2, **kw)
    write_outputs(once, summarise(once), whole)
    names = ["park.csv"] + (["park-reference.csv"] if kw["reference_counts"] else [])
    for name in names:
        rows = _csv_rows(parts / name)
        assert len(rows) == 1 + 4 * 2 * (len(once["n_hf"]) if name == "park.csv" else 1)
        assert rows == _csv_rows(whole / name)
    # Nothing left to run: the folder is rewritten unchanged.
    again = run_benchmark("park", repeats=3, previous=read_outputs("park", parts), **kw)
    write_outputs(again, summarise(again), parts)
    assert _csv_rows(parts / "park.csv") == _csv_rows(whole / "park.csv")


def test_resume_refuses_another_configuration(tmp_path):
    """A folder made with other settings is not extended: the differing field is named, in one
    line, before anything runs."""
    from nearsub.common.analysis.albench import resume_conflict

    result = _result(np.random.default_rng(3))
    write_outputs(result, summarise(result), tmp_path)
    done = subprocess.run(
        [sys.executable, "-m", "nearsub", "al-bench", "park", "--hf-samples", "12", "-o", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr == "nearsub al-bench: cannot resume: the earlier run's hf_samples is 10, this run's 12\n"
    back = read_outputs("park", tmp_path)
    request = {k: back[k] for k in ("problem", "methods", "seed", "hf_samples", "test_points", "settings")}
    request["reference counts"] = [10]
    assert resume_conflict(back, request) is None
    assert "settings.n_lookahead is None, this run's 3" in resume_conflict(
        back, {**request, "settings": {"n_lookahead": 3}}
    )
    assert "reference counts is [10], this run's []" in resume_conflict(back, {**request, "reference counts": []})


def test_reference_kernel_fits_bit_for_bit_like_emukits(monkeypatch):
    """The reference GP's kernel skips work the fit does not use (masks rebuilt at every
    likelihood evaluation, the fixed rho's gradient): its fit and prediction are emukit's, bit
    for bit."""
    from nearsub.common.learning import reference_gp

    if reason := reference_gp.missing():
        pytest.skip(f"reference GP: {reason}")
    from emukit.multi_fidelity.kernels import LinearMultiFidelityKernel

    from nearsub.common.learning.testproblems import get_problem

    park = get_problem("park")
    X = np.random.default_rng(5).uniform(size=(60, 4))
    X_lf, X_hf, X_test = X[:24], X[:7], X[24:]
    args = (park.bounds, X_hf, park.hf(X_hf), X_test)
    kw = dict(lf_data=(X_lf, park.lf(X_lf)), seed=3)
    ours = reference_gp.predict_hf(*args, **kw)
    assert reference_gp._fixed_rho_kernel_class() is not LinearMultiFidelityKernel
    monkeypatch.setattr(reference_gp, "_KERNEL_CLASS", [LinearMultiFidelityKernel])
    emukits = reference_gp.predict_hf(*args, **kw)
    np.testing.assert_array_equal(ours, emukits)
    assert np.mean(np.abs(ours[:, 0] / park.hf(X_test)[:, 0] - 1.0)) < 0.05  # a real fit
