"""Model file: bit-exact round trip, and clear errors for foreign, future or damaged files."""

import json
from datetime import datetime

import numpy as np
import pytest

from nearsub.common.learning.gp import MultiOutputGP
from nearsub.common.surrogate.modelfile import FORMAT_VERSION, ModelFileError, load_model, save_model

BOUNDS = np.array([[-0.7, 0.7], [2.0, 5.0], [5.0, 50.0]])
META = dict(
    input_names=["R_long", "u", "D_ratio"],
    output_names=["X_p", "Y_p", "N_p"],
    units={"u": "kn", "R_long": "-", "X_p": "-"},
    bounds=BOUNDS,
    constraints={"(4.4)": "65.44 (D_sub/D_uuv)^-1 + L/D_uuv - 8 >= 0", "active": True},
    provenance={"method": "unit test", "command": "pytest tests/test_modelfile.py", "notes": "x"},
)


@pytest.fixture(scope="module")
def model():
    rng = np.random.default_rng(0)
    X = BOUNDS[:, 0] + np.ptp(BOUNDS, axis=1) * rng.uniform(size=(30, 3))
    Y = np.column_stack([np.sin(3 * X[:, 0]), X[:, 1] ** 2 / X[:, 2], np.cos(X[:, 0] * X[:, 1])])
    return MultiOutputGP(bounds=BOUNDS, n_restarts=2).fit(X, Y)


@pytest.fixture
def saved(tmp_path, model):
    return save_model(tmp_path / "surrogate.npz", model, **META)


def test_round_trip_is_bit_identical(saved, model):
    loaded = load_model(saved)
    Xt = BOUNDS[:, 0] + np.ptp(BOUNDS, axis=1) * np.random.default_rng(1).uniform(size=(500, 3))
    for a, b in zip(model.predict(Xt, return_std=True), loaded.model.predict(Xt, return_std=True), strict=True):
        assert np.array_equal(a, b)
    for a, b in zip(model.predict_point(Xt[0]), loaded.model.predict_point(Xt[0]), strict=True):
        assert np.array_equal(a, b)
    assert loaded.input_names == tuple(META["input_names"])
    assert loaded.output_names == tuple(META["output_names"])
    assert loaded.units == META["units"]
    assert np.array_equal(loaded.bounds, BOUNDS)
    assert loaded.constraints == META["constraints"]
    assert loaded.format_version == FORMAT_VERSION
    assert loaded.provenance["command"] == META["provenance"]["command"]
    created = datetime.fromisoformat(loaded.provenance["created_utc"])
    assert created.utcoffset().total_seconds() == 0
    for gp, gp2 in zip(model.gps, loaded.model.gps, strict=True):
        assert np.array_equal(gp.theta_, gp2.theta_)
        assert np.array_equal(gp.X_train_, gp2.X_train_)
    assert not list(saved.parent.glob(".*.tmp"))  # the atomic write cleaned up


def _rewrite(path, change_meta=None, drop=()):
    with np.load(path, allow_pickle=False) as npz:
        entries = {k: npz[k] for k in npz.files if k not in drop}
    if change_meta:
        meta = json.loads(entries["metadata"].tobytes())
        change_meta(meta)
        entries["metadata"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    with open(path, "wb") as f:
        np.savez(f, **entries)


def test_unknown_version_is_rejected(saved):
    _rewrite(saved, lambda meta: meta.update(version=FORMAT_VERSION + 98))
    with pytest.raises(ModelFileError, match="unsupported format version 99") as exc:
        load_model(saved)
    assert str(saved) in str(exc.value)


def test_foreign_format_is_rejected(saved, tmp_path):
    _rewrite(saved, lambda meta: meta.update(format="something-else"))
    with pytest.raises(ModelFileError, match="not a nearsub model file"):
        load_model(saved)
    plain = tmp_path / "plain.npz"
    np.savez(plain, a=np.arange(3))
    with pytest.raises(ModelFileError, match="no 'metadata' entry"):
        load_model(plain)
    npy = tmp_path / "array.npy"
    np.save(npy, np.arange(3))
    with pytest.raises(ModelFileError, match="not an .npz archive"):
        load_model(npy)


def test_truncated_file_is_rejected(saved):
    data = saved.read_bytes()
    saved.write_bytes(data[: len(data) // 2])
    with pytest.raises(ModelFileError, match="corrupt") as exc:
        load_model(saved)
    assert str(saved) in str(exc.value)


def test_flipped_bytes_are_detected(saved):
    data = bytearray(saved.read_bytes())
    start = data.index(b"model/gp1/alpha")  # local header name; the array data follows it
    data[start + 200] ^= 0xFF
    saved.write_bytes(bytes(data))
    with pytest.raises(ModelFileError, match="corrupt"):
        load_model(saved)


def test_missing_entry_and_garbage_are_rejected(saved, tmp_path):
    _rewrite(saved, drop=("model/gp0/L_inv",))
    with pytest.raises(ModelFileError, match="inconsistent model file.*L_inv"):
        load_model(saved)
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"this is not a model")
    with pytest.raises(ModelFileError, match="corrupt"):
        load_model(garbage)
    with pytest.raises(ModelFileError, match="no such file"):
        load_model(tmp_path / "missing.npz")


def test_save_validates_metadata(tmp_path, model):
    bad = [
        dict(input_names=["a", "b"]),
        dict(output_names=["X_p", "Y_p", "R_long"]),
        dict(units={"speed": "kn"}),
        dict(bounds=BOUNDS[::-1, ::-1]),
        dict(provenance={"when": datetime.now()}),
    ]
    for change in bad:
        with pytest.raises(ValueError):
            save_model(tmp_path / "m.npz", model, **{**META, **change})
    assert not list(tmp_path.iterdir())


# ------------------------------------------------------------------------- LF in the loop
@pytest.fixture(scope="module")
def in_loop(tmp_path_factory):
    from nearsub.common.hydro.low_fidelity import lf_coefficients
    from nearsub.common.surrogate.domain import sample_feasible
    from nearsub.common.surrogate.model import save_surrogate
    from nearsub.common.surrogate.training import fit_model

    X = sample_feasible(25, seed=5)
    Y = 1.1 * lf_coefficients(X) + 1e-4 * np.sin(X[:, [0]] * 4.0)  # a made-up "HF"
    path = tmp_path_factory.mktemp("in-loop") / "surrogate.npz"
    return save_surrogate(path, fit_model(X, Y), {"method": "unit test"})


def test_lf_in_the_loop_predicts_lf_plus_delta_and_round_trips(in_loop):
    from nearsub.common.hydro.low_fidelity import lf_coefficients
    from nearsub.common.surrogate.domain import sample_feasible
    from nearsub.common.surrogate.model import Surrogate, load_surrogate

    s = load_surrogate(in_loop)
    assert s.kind == "lf_in_loop"
    X = sample_feasible(40, seed=6)
    p = s.predict(X)
    delta, delta_std = s.discrepancy(X)
    assert np.array_equal(s.low_fidelity(X), lf_coefficients(X))
    assert np.array_equal(p.mean, lf_coefficients(X) + delta) and np.array_equal(p.std, delta_std)
    assert s.discrepancy(X, return_std=False)[1] is None
    single = np.vstack([s.predict(X[i]).mean for i in range(len(X))])
    assert np.array_equal(single, p.mean)
    # Outside the LF's field (UUV inside the hull, far behind it): finite, and flagged.
    far = s.predict([[0.0, 0.03, 3.0, 0.0, 20.0, 8.0], [3.0, 0.07, 3.0, 0.0, 20.0, 8.0]])
    assert np.all(np.isfinite(far.mean)) and not far.valid.any()
    old = Surrogate(load_model(in_loop))  # the same file through the generic path
    assert old.model_id == s.model_id


def test_old_kinds_have_no_low_fidelity_or_discrepancy(saved):
    from nearsub.common.surrogate.model import Surrogate, analytic_model

    s = Surrogate(analytic_model(n=12))
    assert s.kind == "gp"
    for call in (s.low_fidelity, s.discrepancy):
        with pytest.raises(TypeError, match="only an LF-in-the-loop model"):
            call(np.zeros((1, 6)))


def test_a_model_file_refuses_a_different_low_fidelity_naming_both(in_loop, monkeypatch):
    from nearsub.common.hydro import low_fidelity as hydro_lf

    monkeypatch.setattr(hydro_lf, "LF_VERSION", hydro_lf.LF_VERSION + 1)
    with pytest.raises(ModelFileError) as error:
        load_model(in_loop)
    text = str(error.value)
    assert "different low fidelity" in text
    assert f"'version': {hydro_lf.LF_VERSION - 1}" in text and f"'version': {hydro_lf.LF_VERSION}" in text


def test_a_model_file_refuses_a_changed_lf_with_the_same_version(in_loop, monkeypatch):
    from nearsub.common.hydro import low_fidelity as hydro_lf

    original = hydro_lf.lf_coefficients
    monkeypatch.setattr(hydro_lf, "lf_coefficients", lambda X, **kw: 1.01 * original(X, **kw))
    with pytest.raises(ModelFileError, match="other values at its probe points"):
        load_model(in_loop)


def test_warping_round_trips_and_maps_the_feasible_set_into_its_box():
    from nearsub.common.surrogate.domain import sample_feasible
    from nearsub.common.surrogate.warping import DEFAULT_WARPING, Warping, clearance_ratio

    w = Warping(DEFAULT_WARPING)
    X = sample_feasible(2000, seed=7)
    W = w.forward(X)
    np.testing.assert_allclose(w.inverse(W), X, rtol=1e-12, atol=1e-14)
    assert np.all((W >= w.bounds[:, 0] - 1e-12) & (W <= w.bounds[:, 1] + 1e-12))
    np.testing.assert_allclose(W[:, 1], np.log(clearance_ratio(X[:, 1], X[:, 4])))
    np.testing.assert_allclose(W[:, 4], np.log(X[:, 4]))
    with pytest.raises(ValueError, match="unknown 'cube'"):
        Warping(("identity", "cube", "identity", "identity", "identity", "identity"))
