"""The viscous correction (common/surrogate/viscous.py, `nearsub cfd correct`): its fit, its file,
where it acts, how the interaction applies it, and the shipped one against the RANS stations it
never saw."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nearsub.common.analysis import rans_comparison
from nearsub.common.hydro import rans, rans_campaign
from nearsub.common.physics.vehicles import SDV
from nearsub.common.surrogate import interaction, viscous
from nearsub.common.surrogate.model import load_surrogate
from nearsub.tools.cli import main

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "docs" / "hydro" / "rans" / "cases"


def synthetic(n: int = 14, seed: int = 1):
    """Rows along the stern and midbody, a smooth 'RANS' interaction, and an 'increment' that is
    right in X', missing Y' entirely and off by a smooth amount in N'."""
    rng = np.random.default_rng(seed)
    rows = np.column_stack(
        [
            rng.uniform(-0.5, 0.3, n),
            rng.uniform(0.06, 0.085, n),
            np.full(n, 3.4),
            np.zeros(n),
            np.full(n, 19.55),
            np.full(n, 10.0),
        ]
    )
    f = viscous.features(rows)
    truth = 1e-3 * np.column_stack([np.sin(3 * f[:, 0]), -np.exp(-f[:, 1]) * (1 + f[:, 0]), np.cos(2 * f[:, 0])])
    increment = truth * [1.0, 0.0, 1.0] + 1e-3 * np.column_stack([0 * f[:, 0], 0 * f[:, 0], 0.3 + 0.2 * f[:, 0]])
    return rows, truth, increment


def test_each_output_gets_the_form_its_leave_one_out_error_prefers():
    rows, truth, increment = synthetic()
    fitted = viscous.fit(rows, truth, increment, {"surrogate_model_id": "abc"}, n_restarts=3)
    assert fitted.meta["forms"][0] == "none"  # the increment is already right
    assert fitted.meta["forms"][1] != "none" and fitted.meta["forms"][2] != "none"
    loo = fitted.meta["loo_mae"]
    for j, form in enumerate(fitted.meta["forms"]):
        assert loo[form][j] == min(loo[f][j] for f in viscous.FORMS)
    change = fitted.blend(rows, increment)
    assert np.all(change[:, 0] == 0.0)
    # at its own stations it takes the increment most of the way to the truth
    assert np.mean(np.abs(increment + change - truth)[:, 1:]) < 0.2 * np.mean(np.abs(increment - truth)[:, 1:])


def test_the_file_reads_back_to_the_bit_and_names_its_model(tmp_path):
    rows, truth, increment = synthetic()
    fitted = viscous.fit(rows, truth, increment, {"surrogate_model_id": "abc"}, n_restarts=2)
    path = viscous.save(tmp_path / "m-viscous.json", fitted)
    again = viscous.load(path)
    probe = synthetic(5, seed=9)[0]
    assert np.array_equal(again.blend(probe, np.zeros((5, 3))), fitted.blend(probe, np.zeros((5, 3))))
    assert viscous.find("abc", tmp_path / "m.npz").surrogate_model_id == "abc"
    assert viscous.find("another", tmp_path / "m.npz") is None
    (tmp_path / "bad-viscous.json").write_text("{}")
    with pytest.raises(viscous.CorrectionFileError, match="bad-viscous.json"):
        viscous.load(tmp_path / "bad-viscous.json")


def test_it_reaches_no_farther_than_the_stations():
    rows = np.array([[-0.45, 0.04, 3.4, 0, 19.55, 10], [0.0, 0.085, 3.4, 0, 19.55, 10], [0.0, 0.11, 3.4, 0, 19.55, 10],
                     [-0.65, 0.02, 3.4, 0, 19.55, 10], [0.7, 0.05, 3.4, 0, 19.55, 10]])  # fmt: skip
    assert viscous.reach(rows).tolist() == [1.0, 1.0, 0.0, 0.0, 0.0]
    between = viscous.reach(np.array([[0.0, 0.1, 3.4, 0, 19.55, 10]]))[0]
    assert 0.0 < between < 1.0


def test_the_shipped_correction_belongs_to_the_shipped_model():
    model = load_surrogate()
    shipped = viscous.load(viscous.default_path())
    assert shipped.surrogate_model_id == model.model_id
    assert interaction.viscous_correction(model) is not None
    assert set(shipped.meta["stations"]).isdisjoint(
        rans.two_body_case(s.row).case_id for s in rans_campaign.TWO_BODY_STATIONS if s.held_out
    )


def test_interaction_at_adds_the_change_only_where_it_acts_and_only_when_asked():
    model = load_surrogate()
    stern = np.array([1.75, 0.0, 0.0, -0.45 * 88.86, 0.0391 * 88.86, 0.0])  # u, v, r, x, y, psi
    far = np.array([1.75, 0.0, 0.0, 0.0, 20.0, 0.0])
    for state, acts in ((stern, True), (far, False)):
        on = interaction.interaction_at(model, state, SDV, 1025.0, "increment")
        off = interaction.interaction_at(model, state, SDV, 1025.0, "increment", viscous=False)
        assert np.all(off.viscous == 0.0)
        if acts:
            assert np.any(on.viscous != 0.0)
            np.testing.assert_allclose(on.forces, off.forces + on.viscous, rtol=1e-12, atol=1e-9)
        else:
            assert np.array_equal(on.forces, off.forces) and np.all(on.viscous == 0.0)
    replace = interaction.interaction_at(model, stern, SDV, 1025.0, "replace")
    assert np.all(replace.viscous == 0.0)  # the thesis's modes never use it


def test_on_the_held_out_rans_stations_the_product_is_closer_to_rans_than_the_panel_hf():
    """Issue item: on RANS stations kept out of training, the shipped interaction must be closer to
    RANS than the panel HF is, output by output (the interaction alone: each station less its UUV
    alone; docs/hydro/rans/two-body-interaction.md)."""
    found = rans_campaign.results([CASES])
    results = rans_comparison.two_body_converged(found)
    truth = rans_comparison.rans_interaction(results, rans_comparison.uuv_alone(found))
    held = [
        i
        for i, r in enumerate(results)
        if r.level == "medium" and rans_campaign.station_of(r.inputs).held_out and np.isfinite(truth[i]).all()
    ]
    assert len(held) >= 8
    model = load_surrogate()
    rows = np.array([results[i].inputs for i in held])
    values = rans_comparison.interaction_values(rows, model, interaction.viscous_correction(model))
    product = np.mean(np.abs(values[rans_comparison.CORRECTED] - truth[held]), axis=0)
    panel = np.mean(np.abs(values["panel HF"] - truth[held]), axis=0)
    assert np.all(product < panel), (product, panel)


def test_correct_writes_a_new_file_and_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "c.json"
    assert main(["cfd", "correct", "--from", str(CASES), "-o", str(out)]) == 0
    fitted = viscous.load(out)
    assert fitted.surrogate_model_id == load_surrogate().model_id and len(fitted.meta["stations"]) >= 10
    assert main(["cfd", "correct", "--from", str(CASES), "-o", str(out)]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["cfd", "correct", "--from", str(tmp_path), "-o", str(tmp_path / "d.json")]) == 2
    assert "training station" in capsys.readouterr().err
    for model in (tmp_path / "missing.npz", out):  # no file; a file that is not a model
        assert main(["cfd", "correct", "--model", str(model), "-o", str(tmp_path / "e.json")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("nearsub cfd correct: --model") and len(err.strip().splitlines()) == 1


def test_an_unreadable_correction_beside_a_model_is_one_line_naming_it(tmp_path):
    import shutil

    from nearsub.common.surrogate.model import default_model_path

    model_file = tmp_path / "m.npz"
    shutil.copy(default_model_path(), model_file)
    viscous.path_for(model_file).write_text("not json")
    model = load_surrogate(model_file)
    state = np.array([1.75, 0.0, 0.0, -0.45 * 88.86, 0.0391 * 88.86, 0.0])
    with pytest.raises(interaction.IncrementError, match="m-viscous.json") as caught:
        interaction.interaction_at(
            model, state, SDV, 1025.0, "increment", free_stream=interaction.increment_table(load_surrogate())
        )
    assert len(str(caught.value).splitlines()) == 1 and "surrogate.viscous = false" in str(caught.value)
    off = interaction.interaction_at(
        model, state, SDV, 1025.0, "increment", free_stream=interaction.increment_table(load_surrogate()), viscous=False
    )
    assert np.all(off.viscous == 0.0)
