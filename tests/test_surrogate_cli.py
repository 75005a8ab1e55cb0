"""`nearsub surrogate info|predict` and `nearsub bench surrogate`, through their own parsers (the
commands are wired into tools/cli.py separately)."""

import argparse
import json
import subprocess
import sys

import numpy as np
import pytest

from nearsub.common.surrogate import domain
from nearsub.common.surrogate import model as sg
from nearsub.common.surrogate.modelfile import load_model
from nearsub.tools.commands.surrogate import (
    add_bench_parser,
    add_parser,
    bench_surrogate,
    child_env,
    write_analytic_model,
)

POINT = {"R_long": 0.1, "R_lat": 0.07, "u_kn": 3.5, "psi_deg": 0.5, "d_ratio": 14.0, "ld_ratio": 7.24}


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    return write_analytic_model(tmp_path_factory.mktemp("surrogate") / "analytic.npz")


def run(capsys, *argv):
    """Parse like `nearsub ...` would and run the command."""
    parser = argparse.ArgumentParser(prog="nearsub")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args([str(a) for a in argv])
    code = args.func(args)
    out, err = capsys.readouterr()
    return code, out, err


def assignments(point=POINT):
    return [f"{k}={v}" for k, v in point.items()]


def test_info_shows_domain_training_size_hyperparameters_and_provenance(capsys, model_path):
    code, out, _ = run(capsys, "surrogate", "info", model_path)
    assert code == 0
    assert "100 points, 6 inputs, 3 outputs" in out and "ANALYTIC TEST FIXTURE" in out
    assert "R_lat" in out and "0.059" in out and "(4.4)" in out and "length scales" in out
    code, out, _ = run(capsys, "surrogate", "info", model_path, "--json")
    info = json.loads(out)
    assert [i["name"] for i in info["inputs"]] == list(domain.INPUT_NAMES)
    assert info["inputs"][2]["bounds"] == [2.0, 5.0] and info["inputs"][2]["unit"] == "kn"
    assert info["training_points"] == 100 and set(info["inputs"][0]["length_scales"]) == set(domain.OUTPUT_NAMES)
    assert info["provenance"]["n_train"] == 100 and info["outputs"][0]["signal_std"] > 0


def test_predict_prints_mean_std_and_flags(capsys, model_path):
    expected = sg.Surrogate(load_model(model_path)).predict(np.array(list(POINT.values())))
    code, out, _ = run(capsys, "surrogate", "predict", model_path, *assignments(), "--json")
    result = json.loads(out)
    assert code == 0 and result["in_domain"] and result["constraints_ok"]
    assert [result["mean"][n] for n in domain.OUTPUT_NAMES] == expected.mean[0].tolist()
    assert [result["std"][n] for n in domain.OUTPUT_NAMES] == expected.std[0].tolist()
    code, out, _ = run(capsys, "surrogate", "predict", model_path, *assignments())
    assert code == 0 and "X_p =" in out and "+/-" in out and "in domain (table 4.2):   yes" in out


def test_predict_flags_points_outside_the_domain_and_constraints(capsys, model_path):
    point = {**POINT, "R_long": 0.9, "R_lat": 0.059}
    code, out, _ = run(capsys, "surrogate", "predict", model_path, *assignments(point), "--json")
    result = json.loads(out)
    assert code == 0 and not result["in_domain"] and not result["constraints_ok"]
    assert result["outside_bounds"] == ["R_long"] and result["violated_constraints"] == ["(4.4)"]
    code, out, _ = run(capsys, "surrogate", "predict", model_path, *assignments(point))
    assert "NO, outside: R_long" in out and "VIOLATED: (4.4)" in out


@pytest.mark.parametrize(
    "items, expected",
    [
        (assignments()[:5], "missing inputs: ld_ratio"),
        ([*assignments(), "speed=3"], "got 'speed=3'"),
        ([*assignments()[:5], "ld_ratio=abc"], "ld_ratio: not a number"),
    ],
)
def test_predict_rejects_bad_arguments(capsys, model_path, items, expected):
    code, _, err = run(capsys, "surrogate", "predict", model_path, *items)
    assert code == 2 and expected in err


def test_a_bad_model_file_is_reported(capsys, tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a model")
    code, _, err = run(capsys, "surrogate", "info", bad)
    assert code == 2 and "corrupt or unreadable" in err


def test_without_a_model_the_fallback_is_announced(capsys, monkeypatch, tmp_path, model_path):
    monkeypatch.setattr(sg, "default_model_path", lambda: tmp_path / "missing.npz")
    monkeypatch.setattr(sg, "analytic_model", lambda: load_model(model_path))  # skip the fit
    code, out, err = run(capsys, "surrogate", "predict", *assignments())
    assert code == 0 and "WARNING: no shipped surrogate model" in err and "X_p =" in out
    code, out, err = run(capsys, "surrogate", "info")
    assert code == 0 and "analytic test fixture (no model at" in out


def test_bench_subcommand_is_registered():
    parser = argparse.ArgumentParser(prog="nearsub")
    bench = parser.add_subparsers(dest="command").add_parser("bench")
    add_bench_parser(bench.add_subparsers(dest="bench_command", required=True))
    bench.set_defaults(func=None)  # tools/cli.py's bench default must not win over the leaf's
    args = parser.parse_args(["bench", "surrogate", "--repeats", "5", "--fit-repeats", "1", "--json"])
    assert args.func is bench_surrogate and (args.repeats, args.fit_repeats, args.json) == (5, 1, True)


@pytest.mark.timeout(120)
def test_bench_reports_every_figure():
    # In a child with one BLAS thread, as the apps run: threaded BLAS on a busy machine makes the
    # timed fits 10x slower and this test slow.
    code = (
        "import argparse, sys; from nearsub.tools.commands.surrogate import bench_surrogate; "
        "sys.exit(bench_surrogate(argparse.Namespace(repeats=50, fit_repeats=1, json=True)))"
    )
    done = subprocess.run([sys.executable, "-c", code], env=child_env(), capture_output=True, text=True, timeout=100)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["query_equals_inprocess"] and result["blas_threads"] == "1"
    for key in (
        "point_core_us",
        "batch_10000_ms",
        "query_median_us",
        "query_p99_us",
        "published_median_us",
        "fit_3_outputs_s",
    ):
        assert result[key] > 0
    assert result["targets"]["point_us"] == 50.0
    assert result["lf_in_loop"]["point_us"] > result["lf_in_loop"]["lf_point_us"] > 0  # the shipped model
