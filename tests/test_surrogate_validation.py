"""`nearsub surrogate validate`: Latin-hypercube test points within the constraints, HF values on a
process pool, MAE and the REMUS 100 error equivalents of thesis table 4.3."""

import json
import math

import numpy as np
import pytest

from conftest import ROOT
from nearsub.common.hydro import high_fidelity as hydro_hf
from nearsub.common.physics.vehicles import REMUS100
from nearsub.common.surrogate.domain import constraints_ok, in_domain
from nearsub.common.surrogate.validation import (
    THESIS_MAE,
    error_equivalents,
    evaluate_rows,
    latin_hypercube_feasible,
    mean_absolute_error,
)
from nearsub.tools.cli import main

pytestmark = pytest.mark.timeout(180)


def test_latin_hypercube_points_are_feasible_and_follow_the_seed():
    X = latin_hypercube_feasible(60, seed=3)
    assert X.shape == (60, 6)
    assert in_domain(X).all() and constraints_ok(X).all()
    assert np.array_equal(X, latin_hypercube_feasible(60, seed=3))
    assert not np.array_equal(X, latin_hypercube_feasible(60, seed=4))
    # Each hypercube stratum holds at most one point: no two points share a value of any input.
    assert all(len(np.unique(X[:, k])) == len(X) for k in range(6))


def test_error_equivalents_use_the_remus_100_rudder_and_drag():
    q = 0.5 * REMUS100.rho
    length = REMUS100.length
    mae = [
        0.01 * abs(REMUS100.X_uu) / (q * length**2),  # 1 % of the thrust that holds any speed
        math.radians(1.0) * REMUS100.Y_uudr / (q * length**2),  # the sway force of 1 deg of rudder
        math.radians(2.0) * abs(REMUS100.N_uudr) / (q * length**3),  # the yaw moment of 2 deg
    ]
    assert error_equivalents(mae) == pytest.approx([1.0, 1.0, 2.0], rel=1e-12)


def test_the_thesis_mae_through_this_conversion_is_not_its_printed_equivalents():
    # Pinned: the thesis's conversion is unstated, and ours gives 2.2-4x its printed 10.26 %, 1.78, 3.95 deg.
    assert error_equivalents(THESIS_MAE) == pytest.approx([41.93, 3.890, 8.570], abs=0.005)


def test_mean_absolute_error_leaves_out_rows_the_hf_could_not_evaluate():
    actual = np.array([[1.0, 2.0, 3.0], [np.nan, np.nan, np.nan], [0.0, 0.0, 0.0]])
    predicted = np.array([[2.0, 2.0, 1.0], [5.0, 5.0, 5.0], [1.0, -1.0, 0.0]])
    assert mean_absolute_error(predicted, actual) == pytest.approx([1.0, 0.5, 1.0])


def test_a_process_pool_gives_the_same_hf_values_as_one_process():
    X = latin_hypercube_feasible(2, seed=5)
    function = hydro_hf.hf_coefficients
    serial, _ = evaluate_rows(function, X, jobs=1)
    pooled, seconds = evaluate_rows(function, X, jobs=2)
    assert np.array_equal(serial, pooled)
    assert seconds.shape == (2,) and np.all(seconds > 0)


def test_validate_prints_table_4_3_and_writes_every_point(tmp_path, capsys):
    out = tmp_path / "validation.json"
    code = main(["surrogate", "validate", "--points", "3", "--panels", "coarse", "--seed", "1", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0
    assert "7.492e-04" in text and "% X_prop" in text and "d_eq,N" in text and "COARSE" in text
    result = json.loads(out.read_text())
    rows = result["rows"]
    assert len(rows) == 3 and result["summary"]["evaluated"] == 3
    X = np.array([[r[k] for k in ("R_long", "R_lat", "u_kn", "psi_deg", "d_ratio", "ld_ratio")] for r in rows])
    assert np.array_equal(X, latin_hypercube_feasible(3, seed=1))
    hf = np.array([[r[f"{n}_hf"] for n in ("X_p", "Y_p", "N_p")] for r in rows])
    assert np.array_equal(hf, hydro_hf.hf_coefficients(X, hydro_hf.COARSE))
    pred = np.array([[r[f"{n}_pred"] for n in ("X_p", "Y_p", "N_p")] for r in rows])
    assert result["summary"]["mae"] == pytest.approx(np.mean(np.abs(pred - hf), axis=0).tolist(), rel=1e-12)
    assert result["summary"]["equivalents"] == pytest.approx(error_equivalents(result["summary"]["mae"]).tolist())


def test_validate_rejects_an_output_it_cannot_write(tmp_path, capsys):
    code = main(["surrogate", "validate", "--points", "2", "--out", str(tmp_path / "result.txt")])
    err = capsys.readouterr().err
    assert code == 2 and "result.txt" in err and ".json or .csv" in err


POINTS_FILE = ROOT / "docs" / "hydro" / "validation-points.csv"


def test_validate_with_a_points_file_reproduces_the_mae_computed_directly(tmp_path, capsys):
    from nearsub.common.hydro.low_fidelity import lf_coefficients
    from nearsub.common.surrogate.model import load_surrogate

    out = tmp_path / "validation.json"
    assert main(["surrogate", "validate", "--points-file", str(POINTS_FILE), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "LF MAE" in text and "2-sigma" in text and "500 points with HF values" in text
    summary = json.loads(out.read_text())["summary"]
    data = np.genfromtxt(POINTS_FILE, delimiter=",", names=True)
    X = np.column_stack([data[k] for k in ("R_long", "R_lat", "u_kn", "psi_deg", "d_ratio", "ld_ratio")])
    hf = np.column_stack([data[f"{n}_hf"] for n in ("X_p", "Y_p", "N_p")])
    p = load_surrogate().predict(X)
    assert summary["mae"] == pytest.approx(np.mean(np.abs(p.mean - hf), axis=0).tolist(), rel=1e-12)
    assert summary["lf_mae"] == pytest.approx(np.mean(np.abs(lf_coefficients(X) - hf), axis=0).tolist(), rel=1e-12)
    within = np.mean(np.abs(p.mean - hf) <= 2.0 * p.std, axis=0)
    assert summary["fraction_within_2_std"] == pytest.approx(within.tolist())


@pytest.mark.parametrize(
    "row, message",
    [
        ("0.1,0.07,abc,0,20,8,1e-4,1e-4,1e-4", "row 2 (line 3), column u_kn: 'abc' is not a number"),
        ("0.1,0.07,3,inf,20,8,1e-4,1e-4,1e-4", "row 2 (line 3), column psi_deg: 'inf' is not finite"),
        ("0.1,0.07,3,0,20,8,1e-4,,1e-4", "row 2 (line 3), column Y_p_hf: '' is not a number"),
    ],
)
def test_validate_names_the_row_column_and_value_of_a_bad_points_file(tmp_path, capsys, row, message):
    path = tmp_path / "points.csv"
    header = "R_long,R_lat,u_kn,psi_deg,d_ratio,ld_ratio,X_p_hf,Y_p_hf,N_p_hf"
    path.write_text(f"{header}\n0.1,0.07,3,0,20,8,1e-4,1e-4,1e-4\n{row}\n")
    assert main(["surrogate", "validate", "--points-file", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_validate_names_a_missing_points_file_column(tmp_path, capsys):
    path = tmp_path / "points.csv"
    path.write_text("R_long,R_lat,u_kn,psi_deg,d_ratio,ld_ratio,X_p,Y_p,N_p\n0.1,0.07,3,0,20,8,1,1,1\n")
    assert main(["surrogate", "validate", "--points-file", str(path)]) == 2
    assert "missing column(s) X_p_hf, Y_p_hf, N_p_hf" in capsys.readouterr().err
