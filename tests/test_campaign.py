"""`nearsub campaign start|next|tell|export`: NMMF with the user's CFD as the high fidelity
The "CFD" here is nearsub's own HF on coarse panels, told by hand."""

import csv
import json

import numpy as np
import pytest

from nearsub.common.hydro import high_fidelity as hydro_hf
from nearsub.common.physics.hull import D_SUB, L_SUB, SUB_CB_FROM_NOSE
from nearsub.common.physics.proximity import closest_distance
from nearsub.common.surrogate.campaign_cases import case_geometry
from nearsub.common.surrogate.domain import KNOT, to_coefficients, to_forces
from nearsub.common.surrogate.modelfile import MultiFidelitySurrogate, load_model
from nearsub.tools.cli import main

pytestmark = pytest.mark.timeout(300)

ROW = [-0.2, 0.07, 3.5, 1.0, 20.0, 8.0]


def test_a_case_is_the_dimensional_form_of_its_inputs():
    case = case_geometry(ROW)
    diameter = D_SUB / 20.0
    assert case["uuv"]["diameter_m"] == pytest.approx(diameter)
    assert case["uuv"]["length_m"] == pytest.approx(8.0 * diameter)
    assert case["submarine"]["length_m"] == L_SUB and case["submarine"]["diameter_m"] == D_SUB
    assert case["position"]["x_m"] == pytest.approx(-0.2 * L_SUB)
    assert case["position"]["y_m"] == pytest.approx(0.07 * L_SUB)
    assert case["position"]["uuv_cb_behind_submarine_nose_m"] == pytest.approx(SUB_CB_FROM_NOSE + 0.2 * L_SUB)
    clearance = closest_distance(-0.2 * L_SUB, 0.07 * L_SUB, np.radians(1.0), 8.0 * diameter, diameter)
    assert case["position"]["clearance_m"] == pytest.approx(float(clearance)) and clearance > 0
    assert case["speed_m_s"] == pytest.approx(3.5 * KNOT) and case["heading_deg"] == 1.0


def test_forces_and_coefficients_convert_both_ways():
    coefficients = np.array([[-1.2e-3, 3.0e-4, -5.0e-4]])
    forces = to_forces(coefficients, 1.0, 1.8, 4.1)
    assert np.allclose(to_coefficients(forces, 1.8, 4.1), coefficients, rtol=1e-14, atol=0.0)


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def pending(capsys, state):
    code, out, _ = run(capsys, "campaign", "next", "--state", state, "--json")
    assert code == 0
    return json.loads(out)


def test_a_campaign_told_by_hand_trains_a_model_with_the_answers(tmp_path, capsys):
    state = tmp_path / "cfd.json"
    code, out, err = run(capsys, "campaign", "start", "--state", state, "--budget", 3, "--n-lf0", 4, "--n-hf0", 2)
    assert code == 0 and "case 2.1" in out and "case 2.2" in out and "m abeam" in out
    assert run(capsys, "campaign", "start", "--state", state)[0] == 2  # never overwritten by accident

    cases = pending(capsys, state)["cases"]
    assert [c["case"] for c in cases] == ["2.1", "2.2"]
    rows = np.array([list(c["inputs"].values()) for c in cases])
    answers = hydro_hf.hf_coefficients(rows, hydro_hf.COARSE)

    code, _, err = run(capsys, "campaign", "tell", "--state", state, "--X", 1, "--Y", 2, "--N", 3)
    assert code == 2 and "2.1, 2.2" in err  # two cases open: which one?
    x, y, n = answers[0]
    assert run(capsys, "campaign", "tell", "--state", state, "--case", "2.1", "--X", x, "--Y", y, "--N", n)[0] == 0
    assert [c["case"] for c in pending(capsys, state)["cases"]] == ["2.2"]  # kept across invocations
    code, _, err = run(capsys, "campaign", "tell", "--state", state, "--case", "2.2", "--X", "nan", "--Y", 0, "--N", 0)
    assert code == 2 and "--X nan" in err
    x, y, n = answers[1]
    assert run(capsys, "campaign", "tell", "--state", state, "--case", "2.2", "--X", x, "--Y", y, "--N", n)[0] == 0

    third = pending(capsys, state)["cases"]
    assert len(third) == 1 and third[0]["hf_sample"] == 3
    code, _, err = run(capsys, "campaign", "tell", "--state", state, "--case", "2.1", "--X", 0, "--Y", 0, "--N", 0)
    assert code == 2 and "not pending" in err  # a stale case id
    row = np.array(list(third[0]["inputs"].values()))
    answer = hydro_hf.hf_coefficients(row, hydro_hf.COARSE)
    length = third[0]["uuv"]["length_m"]
    forces = to_forces(answer, 1.0, third[0]["speed_m_s"], length)[0]  # told in N and N m
    code, out, _ = run(
        capsys, "campaign", "tell", "--state", state, "--si", "--X", forces[0], "--Y", forces[1], "--N", forces[2]
    )
    assert code == 0 and "campaign complete" in out

    model = tmp_path / "cfd.npz"
    assert run(capsys, "campaign", "export", "--state", state, "--out", model)[0] == 0
    loaded = load_model(model)
    assert isinstance(loaded.model, MultiFidelitySurrogate)
    assert "user-supplied" in loaded.provenance["high_fidelity"]
    with open(tmp_path / "cfd-hf-samples.csv") as fh:
        told = np.array([[float(r[k]) for k in ("X_p", "Y_p", "N_p")] for r in csv.DictReader(fh)])
    assert np.array_equal(told[:2], answers)
    assert np.allclose(told[2], answer[0], rtol=1e-12, atol=0.0)


def test_next_without_a_campaign_says_how_to_start_one(tmp_path, capsys):
    code, _, err = run(capsys, "campaign", "next", "--state", tmp_path / "none.json")
    assert code == 2 and "nearsub campaign start" in err


def test_train_refuses_to_fill_a_cfd_campaign_with_panel_samples(tmp_path, capsys):
    state = tmp_path / "cfd.json"
    assert run(capsys, "campaign", "start", "--state", state, "--budget", 3, "--n-lf0", 3, "--n-hf0", 2)[0] == 0
    code, _, err = run(capsys, "train", "--state", state, "--out", tmp_path / "m.npz")
    assert code == 2 and "not an HF sample store" in err
