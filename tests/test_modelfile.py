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
