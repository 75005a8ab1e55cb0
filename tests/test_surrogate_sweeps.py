"""`nearsub surrogate sweep --hf-from`: a new model's sweep reuses the HF increments of an earlier
one (common/surrogate/sweeps.py), only where the inputs are the same bit for bit."""

import csv
from pathlib import Path

import numpy as np
import pytest

from nearsub.common.physics.vehicles import SDV
from nearsub.common.surrogate import sweeps
from nearsub.common.surrogate.model import load_surrogate
from nearsub.tools.cli import main

SHIPPED = Path(__file__).resolve().parents[1] / "docs" / "hydro" / "sweeps" / "sweeps.csv"


def read(path):
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def test_stored_hf_is_the_earlier_sweeps_and_refuses_other_inputs():
    rows = read(SHIPPED)
    for station, kind, inputs in sweeps.sweep_inputs():
        want = [
            [float(r[f"hf_{c}"]) for c in ("X_p", "Y_p", "N_p")]
            for r in rows
            if (r["station"], r["sweep"]) == (station, kind)
        ]
        np.testing.assert_array_equal(sweeps.stored_hf(rows, station, kind, inputs), want)
    station, kind, inputs = sweeps.sweep_inputs()[0]
    rounded = inputs.copy()
    rounded[3, 1] = np.nextafter(rounded[3, 1], 1.0)  # one R_lat one ulp off: another CPU's rounding
    np.testing.assert_array_equal(
        sweeps.stored_hf(rows, station, kind, rounded), sweeps.stored_hf(rows, station, kind, inputs)
    )
    moved = inputs.copy()
    moved[3, 1] *= 1.0 + 1e-9  # beyond rounding: another sweep's input
    with pytest.raises(ValueError, match=f"{station} {kind} sweep has other inputs"):
        sweeps.stored_hf(rows, station, kind, moved)
    with pytest.raises(ValueError, match="no column"):
        sweeps.stored_hf([{k: v for k, v in r.items() if k != "hf_Y_p"} for r in rows], station, kind, inputs)


# The LF's field table and the model file: about 5 s on a quiet machine, over a minute at a load
# average of 20; the test does no HF runs.
@pytest.mark.timeout(600)
def test_sweep_with_hf_from_writes_those_hf_values_and_the_applied_increment(tmp_path, capsys):
    assert main(["surrogate", "sweep", "--hf-from", str(SHIPPED), "-o", str(tmp_path)]) == 0
    written, shipped = read(tmp_path / "sweeps.csv"), read(SHIPPED)
    assert [r["hf_X_p"] for r in written] == [r["hf_X_p"] for r in shipped]
    assert (tmp_path / "heading.png").exists() and (tmp_path / "lateral.png").exists()
    _, _, inputs = sweeps.sweep_inputs()[1]
    applied = sweeps.applied_increments(load_surrogate(), inputs, SDV)
    lateral = [r for r in written if r["sweep"] == "lateral"][: len(inputs)]
    np.testing.assert_array_equal([float(r["applied_N_p"]) for r in lateral], applied[:, 2])
    capsys.readouterr()
    assert main(["surrogate", "sweep", "--hf-from", str(tmp_path / "missing.csv"), "-o", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--hf-from" in err[0] and "missing.csv" in err[0]
