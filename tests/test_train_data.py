"""`nearsub train --data FILE.csv`: a surrogate fitted to a user's own table, with clear errors
for missing columns, units and out-of-domain rows."""

import csv
import hashlib

import numpy as np
import pytest

from nearsub.common.learning.gp import MultiOutputGP
from nearsub.common.surrogate.domain import INPUT_NAMES, OUTPUT_NAMES
from nearsub.common.surrogate.model import Surrogate, default_model_path
from nearsub.common.surrogate.modelfile import load_model
from nearsub.tools.cli import main

pytestmark = pytest.mark.timeout(120)

SHIPPED_SAMPLES = default_model_path().with_name("surrogate-hf-samples.csv")


def shipped_rows(n=25):
    with open(SHIPPED_SAMPLES) as fh:
        return list(csv.DictReader(fh))[:n]


def write(path, rows, columns=(*INPUT_NAMES, *OUTPUT_NAMES)):
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(columns), extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    return path


def train(capsys, *argv):
    code = main(["train", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_a_table_fits_a_model_that_records_where_it_came_from(tmp_path, capsys):
    rows = shipped_rows()
    data = write(tmp_path / "mine.csv", rows, columns=(*reversed(OUTPUT_NAMES), "note", *INPUT_NAMES))
    code, out, _ = train(capsys, "--data", data, "--out", tmp_path / "mine.npz")
    assert code == 0 and "25 rows" in out
    loaded = load_model(tmp_path / "mine.npz")
    assert isinstance(loaded.model, MultiOutputGP)
    assert loaded.provenance["data_sha256"] == hashlib.sha256(data.read_bytes()).hexdigest()
    assert loaded.provenance["rows"] == 25 and "user-supplied" in loaded.provenance["high_fidelity"]
    X = np.array([[float(r[k]) for k in INPUT_NAMES] for r in rows])
    Y = np.array([[float(r[k]) for k in OUTPUT_NAMES] for r in rows])
    p = Surrogate(loaded).predict(X)
    assert np.all(np.abs(p.mean - Y) <= 0.1 * Y.std(axis=0))  # it learned the table, columns matched by name


def test_data_needs_an_explicit_out(tmp_path, capsys):
    code, _, err = train(capsys, "--data", write(tmp_path / "mine.csv", shipped_rows()))
    assert code == 2 and "--out" in err


def edit(rows, row, column, value):
    rows = [dict(r) for r in rows]
    rows[row][column] = value
    return rows


@pytest.mark.parametrize(
    ("make", "expected"),
    [
        (lambda r: ({k: v for k, v in x.items() if k != "N_p"} for x in r), ["missing column(s) N_p"]),
        (lambda r: edit(r, 1, "u_kn", "3.5 kn"), ["row 2 (line 3)", "u_kn", "'3.5 kn'", "not a number"]),
        (lambda r: edit(r, 2, "psi_deg", "3.0"), ["row 3 (line 4)", "psi_deg", "3 is outside", "[-2, 2]"]),
        (lambda r: edit(r, 0, "X_p", "inf"), ["row 1 (line 2)", "X_p", "'inf'", "not finite"]),
        (lambda r: edit(edit(r, 4, "R_lat", "0.059"), 4, "d_ratio", "5"), ["row 5 (line 6)", "(4.4)"]),
        (lambda r: r[:1], ["1 data row(s)", "at least 2"]),
    ],
    ids=["missing-column", "unit-in-value", "out-of-bounds", "not-finite", "constraint", "too-few-rows"],
)
def test_a_bad_table_is_refused_in_one_line_naming_file_row_column_and_value(tmp_path, capsys, make, expected):
    rows = list(make(shipped_rows()))
    columns = [c for c in (*INPUT_NAMES, *OUTPUT_NAMES) if c in rows[0]]
    data = write(tmp_path / "bad.csv", rows, columns=columns)
    code, _, err = train(capsys, "--data", data, "--out", tmp_path / "bad.npz")
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and str(data) in err
    for text in expected:
        assert text in err
    assert not (tmp_path / "bad.npz").exists()


def test_a_column_in_other_units_gets_a_hint(tmp_path, capsys):
    rows = [{**{k: v for k, v in r.items() if k != "u_kn"}, "u_ms": "1.8"} for r in shipped_rows()]
    data = write(
        tmp_path / "ms.csv", rows, columns=("R_long", "R_lat", "u_ms", "psi_deg", "d_ratio", "ld_ratio", *OUTPUT_NAMES)
    )
    code, _, err = train(capsys, "--data", data, "--out", tmp_path / "ms.npz")
    assert code == 2 and "missing column(s) u_kn" in err and "not m/s" in err
