"""Surrogate domain: bounds, constraints (4.4)-(4.7), mirroring, unit conversions, the analytic
fixture, prediction flags and the query/reply messages."""

import math

import msgpack
import numpy as np
import pytest

from nearsub.common.physics.hull import D_SUB, L_SUB
from nearsub.common.runtime.messages import MessageError
from nearsub.common.surrogate import domain
from nearsub.common.surrogate import model as sg
from nearsub.common.surrogate.modelfile import ModelFileError, load_model
from nearsub.tools.commands.surrogate import write_analytic_model

# A feasible mid-domain point: Explorer-like UUV (table 4.1: D_sub/D_uuv 14.0, L/D 7.24).
MID = np.array([0.1, 0.07, 3.5, 0.5, 14.0, 7.24])


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    return write_analytic_model(tmp_path_factory.mktemp("surrogate") / "analytic.npz")


@pytest.fixture(scope="module")
def surrogate(model_path):
    return sg.Surrogate(load_model(model_path))


def test_inputs_and_bounds_follow_table_4_2():
    assert domain.INPUT_NAMES == ("R_long", "R_lat", "u_kn", "psi_deg", "d_ratio", "ld_ratio")
    expected = [[-0.7, 0.7], [0.059, 0.105], [2, 5], [-2, 2], [5, 50], [4.3, 13]]
    assert np.array_equal(domain.BOUNDS, np.array(expected, dtype=float))
    assert sg.surrogate_key("alpha") == "nearsub/alpha/surrogate"


def test_in_domain_checks_every_bound_and_rejects_non_finite():
    assert domain.in_domain(MID).tolist() == [True]
    assert domain.in_domain(domain.BOUNDS.T).tolist() == [True, True]  # both corners, ends included
    rows = []
    for k in range(6):
        for side, step in ((0, -1e-9), (1, 1e-9)):
            row = MID.copy()
            row[k] = domain.BOUNDS[k, side] + step
            rows.append(row)
    assert not domain.in_domain(np.array(rows)).any()
    bad = np.tile(MID, (3, 1))
    bad[0, 0], bad[1, 3], bad[2, 4] = np.nan, np.inf, -np.inf
    assert not domain.in_domain(bad).any()
    with pytest.raises(ValueError, match="shape"):
        domain.in_domain(np.zeros((2, 5)))


def test_constraints_match_the_printed_equations():
    g = domain.constraint_values(MID)[0]
    r_lat, inv_d, ld = MID[1], 1 / MID[4], MID[5]
    assert g == pytest.approx(
        [
            8.575 * r_lat - 0.5 * inv_d - 9.425e-3 * inv_d * ld - 0.5048,  # (4.4), docs/design.md, "Thesis errata"
            -8.575 * r_lat + 2 * inv_d + 0.5,  # (4.5)
            65.44 * inv_d + ld - 8,  # (4.6)
            -58.81 * inv_d - ld + 17,  # (4.7)
        ],
        rel=1e-12,
    )
    assert domain.constraints_ok(MID).tolist() == [True]


def test_constraint_4_4_is_the_clearance_with_centre_to_centre_r_lat():
    """(4.4) times D_sub is the clearance c - 0.05 m of (4.3) with psi_max = 2 deg, R_lat
    centre-to-centre (errata 7): c = y - D_sub/2 - D_uuv/2 - 0.27 L_uuv sin 2deg."""
    X = domain.sample_feasible(200, seed=3)
    d_uuv = D_SUB / X[:, 4]
    clearance = X[:, 1] * L_SUB - D_SUB / 2 - d_uuv / 2 - 0.27 * X[:, 5] * d_uuv * math.sin(math.radians(2))
    assert np.allclose(domain.constraint_values(X)[:, 0] * D_SUB, clearance - 0.05, atol=2e-3)  # printed constants


def test_the_low_corner_is_infeasible_and_speed_does_not_matter():
    # R_lat = 0.059 violates (4.4) for every UUV size in the domain (docs/design.md, "Thesis errata").
    corners = np.array([[0.0, 0.059, 3.0, 0.0, d, ld] for d in (5.0, 12.0, 50.0) for ld in (4.3, 8.0, 13.0)])
    assert (domain.constraint_values(corners)[:, 0] < 0).all()
    assert not domain.constraints_ok(corners).any()
    # No speed term (errata 3): u and psi do not change feasibility.
    X = domain.sample_feasible(50, seed=1)
    for k, value in ((2, 2.0), (2, 5.0), (3, -2.0)):
        Y = X.copy()
        Y[:, k] = value
        assert np.array_equal(domain.constraint_values(Y), domain.constraint_values(X))


def test_each_constraint_removes_its_region():
    far = MID.copy()
    far[1] = 0.105  # beyond 2 D_uuv + D_sub/2: (4.5)
    long_big = np.array([0.0, 0.09, 3.0, 0.0, 5.0, 13.0])  # a Snakehead-size UUV too long: (4.7)
    short_small = np.array([0.0, 0.062, 3.0, 0.0, 50.0, 4.3])  # a small UUV too short: (4.6)
    g = domain.constraint_values(np.array([far, long_big, short_small]))
    assert g[0, 1] < 0 and g[1, 3] < 0 and g[2, 2] < 0
    assert not domain.constraints_ok(np.array([far, long_big, short_small])).any()


def test_sample_feasible_respects_bounds_and_constraints():
    X = domain.sample_feasible(500, seed=7)
    assert X.shape == (500, 6)
    assert domain.in_domain(X).all() and domain.constraints_ok(X).all()
    assert np.array_equal(X, domain.sample_feasible(500, seed=7))


def test_to_inputs_converts_units_and_mirrors_the_minus_y_side():
    x, y, u, psi = 10.0, 6.0, 2.0 * domain.KNOT, math.radians(1.5)
    inputs, mirror = domain.to_inputs([x, x], [y, -y], u, [psi, psi], 5.36, 0.74)
    assert mirror.tolist() == [1.0, -1.0]
    assert inputs[0] == pytest.approx([x / L_SUB, y / L_SUB, 2.0, 1.5, D_SUB / 0.74, 5.36 / 0.74])
    assert inputs[1] == pytest.approx([x / L_SUB, y / L_SUB, 2.0, -1.5, D_SUB / 0.74, 5.36 / 0.74])
    # headings wrap to [-180, 180) before mirroring
    wrapped, _ = domain.to_inputs(0.0, 6.0, 1.0, 2 * math.pi + psi, 5.36, 0.74)
    assert wrapped[0, 3] == pytest.approx(1.5)
    assert domain.KNOT == pytest.approx(0.514444, rel=1e-6)


def test_to_forces_inverts_the_non_dimensionalisation():
    rho, u, length = 1025.0, 1.8, 3.2
    coeffs = np.array([[-1e-3, 2e-3, -5e-4], [-1e-3, 2e-3, -5e-4]])
    forces = domain.to_forces(coeffs, [1.0, -1.0], u, length, rho)
    q = 0.5 * rho * u**2
    assert forces[0] == pytest.approx([-1e-3 * q * length**2, 2e-3 * q * length**2, -5e-4 * q * length**3])
    assert forces[1] == pytest.approx(forces[0] * [1, -1, -1])
    # and back: X' = X / (0.5 rho u^2 L^2), N' = N / (0.5 rho u^2 L^3) (thesis section 5.2)
    assert forces[0, 0] / (q * length**2) == pytest.approx(-1e-3)
    assert forces[0, 2] / (q * length**3) == pytest.approx(-5e-4)


def test_mirror_symmetry_of_predicted_forces(surrogate):
    """A state at -y gets X equal and Y, N opposite to the mirrored +y state (y -> -y, psi -> -psi)."""
    x, y, u, psi = np.array([5.0, -20.0]), np.array([-6.2, -6.5]), 1.6, np.array([0.01, -0.02])
    minus = surrogate.predict_state(x, y, u, psi, 5.36, 0.74)
    plus = surrogate.predict_state(x, -y, u, -psi, 5.36, 0.74)
    assert minus.in_domain.all() and plus.in_domain.all()
    assert np.array_equal(minus.mean[:, 0], plus.mean[:, 0])
    assert np.array_equal(minus.mean[:, 1:], -plus.mean[:, 1:])
    assert np.array_equal(minus.std, plus.std) and (minus.std > 0).all()


def test_predict_state_scales_mean_and_std(surrogate):
    x, y, u, psi, length, diameter, rho = 3.0, 6.3, 1.5, 0.005, 5.36, 0.74, 1025.0
    inputs, _ = domain.to_inputs(x, y, u, psi, length, diameter)
    coeffs = surrogate.predict(inputs)
    dimensional = surrogate.predict_state(x, y, u, psi, length, diameter, rho)
    q = 0.5 * rho * u**2
    scale = np.array([q * length**2, q * length**2, q * length**3])
    assert dimensional.mean[0] == pytest.approx(coeffs.mean[0] * scale, rel=1e-12)
    assert dimensional.std[0] == pytest.approx(coeffs.std[0] * scale, rel=1e-12)


def test_analytic_fixture_is_labelled_and_plausible(surrogate):
    provenance = surrogate.loaded.provenance
    assert "ANALYTIC TEST FIXTURE" in provenance["method"] and "NOT hydrodynamics" in provenance["method"]
    assert provenance["n_train"] == 100
    assert surrogate.model.gps[0].X_train_.shape == (100, 6)
    assert surrogate.loaded.units["u_kn"] == "kn" and "(4.4)" in surrogate.loaded.constraints
    # Y' and N' change sign along R_long; magnitudes ~1e-3
    line = np.tile([0.0, 0.065, 3.5, 0.0, 20.0, 8.0], (15, 1))
    line[:, 0] = np.linspace(-0.7, 0.7, 15)
    Y = sg.analytic_coefficients(line)
    assert (np.diff(np.sign(Y[:, 1])) != 0).any() and (np.diff(np.sign(Y[:, 2])) != 0).any()
    assert 1e-4 < np.abs(Y).max() < 1e-2 and (Y[:, 0] < 0).all()
    # the GP reproduces the function it was fitted to
    X = domain.sample_feasible(500, seed=11)
    error = surrogate.predict(X, return_std=False).mean - sg.analytic_coefficients(X)
    assert (np.sqrt(np.mean(error**2, axis=0)) < 0.2 * sg.analytic_coefficients(X).std(axis=0)).all()


def test_out_of_domain_points_are_answered_with_the_gp_value_and_flagged(surrogate):
    outside = MID.copy()
    outside[0] = 1.5  # R_long beyond 0.7
    infeasible = np.array([0.0, 0.059, 3.0, 0.0, 20.0, 8.0])  # low corner: (4.4) fails
    nan = MID.copy()
    nan[4] = np.nan
    X = np.array([MID, outside, infeasible, nan])
    p = surrogate.predict(X)
    assert p.in_domain.tolist() == [True, False, True, False]
    assert p.constraints_ok.tolist() == [True, True, False, False]
    assert p.valid.tolist() == [True, False, False, False]
    gp_mean, gp_std = surrogate.model.predict_rows(X, return_std=True)
    assert np.array_equal(p.mean[:3], gp_mean[:3]) and np.array_equal(p.std[:3], gp_std[:3])
    assert np.isnan(p.mean[3]).all() and np.isnan(p.std[3]).all()
    assert (p.std[1] > p.std[0]).all()  # far from the data the std grows
    assert surrogate.predict(MID, return_std=False).std is None


def test_surrogate_refuses_a_model_of_another_domain(tmp_path):
    from nearsub.common.learning.gp import MultiOutputGP
    from nearsub.common.surrogate.modelfile import save_model

    X = np.random.default_rng(0).uniform(size=(10, 2))
    model = MultiOutputGP(n_restarts=1).fit(X, X)
    path = save_model(
        tmp_path / "other.npz",
        model,
        input_names=["a", "b"],
        output_names=["c", "d"],
        units={},
        bounds=[[0, 1], [0, 1]],
        constraints={},
        provenance={},
    )
    with pytest.raises(ModelFileError, match="not a surrogate of this domain"):
        sg.Surrogate(load_model(path))


def test_default_path_and_loud_fallback(monkeypatch, tmp_path, capsys, surrogate):
    assert sg.default_model_path().parts[-3:] == ("nearsub", "data", "surrogate.npz")
    monkeypatch.setattr(sg, "default_model_path", lambda: tmp_path / "missing.npz")
    monkeypatch.setattr(sg, "analytic_model", lambda: surrogate.loaded)  # the fit itself is tested above
    fallback = sg.load_surrogate()
    assert "ANALYTIC TEST FIXTURE" in capsys.readouterr().err
    assert fallback.source.startswith("analytic test fixture") and fallback.model_id == surrogate.model_id
    with pytest.raises(ModelFileError, match="no such file"):
        sg.load_surrogate(tmp_path / "nothing.npz")


def test_model_id_is_a_content_hash(model_path, surrogate):
    again = sg.Surrogate(load_model(model_path))
    assert again.model_id == surrogate.model_id and len(again.model_id) == 16


# ---------------------------------------------------------------------------- messages
def test_answer_query_round_trip_matches_in_process_prediction(surrogate):
    X = domain.sample_feasible(7, seed=2)
    reply = sg.decode_reply(sg.answer_query(surrogate, sg.encode_query(X, step=12, t=0.6, source="sim"), "srv"))
    assert (reply.step, reply.t, reply.source) == (12, 0.6, "srv")
    assert reply.output_names == list(domain.OUTPUT_NAMES) and reply.model_id == surrogate.model_id
    p, expected = reply.prediction(), surrogate.predict(X)
    assert np.array_equal(p.mean, expected.mean) and np.array_equal(p.std, expected.std)
    assert p.in_domain.all() and p.constraints_ok.all()
    one = sg.decode_reply(sg.answer_query(surrogate, sg.encode_query(X[0])))
    assert np.array_equal(one.prediction().mean, surrogate.predict(X[:1]).mean)


def _rows(*rows) -> bytes:
    return np.array(rows, dtype="<f8").tobytes()


def _query(**fields):
    return msgpack.packb({"step": 0, "t": 0.0, **fields})


@pytest.mark.parametrize(
    "payload, expected",
    [
        (b"\xc1\xff", "not valid msgpack"),
        (msgpack.packb([1, 2]), "expected a map"),
        (_query(), "field 'points' = None"),
        (_query(points=b""), "field 'points': 0 bytes"),
        (_query(points=_rows([0.0, 0.07, 3.0, 0.0, 14.0])), "field 'points': 40 bytes"),
        (_query(points=_rows(MID, MID)[:-8]), "field 'points': 88 bytes"),
        (_query(points=_rows(list(MID[:5]) + [float("nan")])), "field 'points.0.5' = nan"),
        (_query(points=_rows(MID, [float("inf")] + list(MID[1:]))), "field 'points.1.0' = inf"),
        (_query(points=[list(MID)]), "field 'points' = [["),  # the lists of floats of version 1
        (_query(points=_rows(MID), extra=1), "field 'extra'"),
        (_query(points=_rows(MID), schema_version=1), "field 'schema_version' = 1: unsupported"),
        (msgpack.packb({"step": -1, "t": 0.0, "points": _rows(MID)}), "field 'step' = -1"),
        (msgpack.packb({"step": 0, "t": float("nan"), "points": _rows(MID)}), "field 't' = nan"),
        (msgpack.packb({"step": 0, "t": 0.0, "source": 3, "points": _rows(MID)}), "field 'source' = 3"),
    ],
)
def test_malformed_queries_name_the_field_and_value(surrogate, payload, expected):
    with pytest.raises(MessageError) as info:
        sg.answer_query(surrogate, payload)
    assert "surrogate query" in str(info.value) and expected in str(info.value)


def test_a_query_over_the_cap_is_refused_before_its_values_are_read(surrogate):
    rows = np.full((5, 6), np.nan)  # not finite: the cap is said first
    with pytest.raises(MessageError, match="5 points in one query; this server answers at most 4 per query"):
        sg.answer_query(surrogate, sg.encode_query(rows), max_points=4)


def test_a_non_finite_prediction_is_refused_not_sent():
    X = domain.sample_feasible(2, seed=3)
    bad = sg.Prediction(np.array([[1.0, 2.0, 3.0], [1.0, np.inf, 3.0]]), np.zeros((2, 3)), *[np.ones(2, bool)] * 2)
    with pytest.raises(ValueError, match=r"field 'mean.1.1' = inf"):
        sg.encode_reply(sg.decode_query(sg.encode_query(X)), bad, list(domain.OUTPUT_NAMES), "x", "srv")


def test_reply_checks_shapes():
    good = dict(
        step=0,
        t=0.0,
        mean=_rows([1.0, 2.0, 3.0]),
        std=_rows([0.1, 0.1, 0.1]),
        in_domain=b"\x01",
        constraints_ok=b"\x00",
        output_names=list(domain.OUTPUT_NAMES),
        model_id="x",
    )
    p = sg.decode_reply(msgpack.packb(good)).prediction()
    assert p.mean.shape == (1, 3) and p.in_domain.tolist() == [True] and p.constraints_ok.tolist() == [False]
    assert not p.mean.flags.writeable  # a view of the reply's bytes
    for change, expected in (
        ({"std": b""}, "mean 1 and std 0 rows"),
        ({"mean": _rows([1.0, 2.0])}, "mean 0.666667"),
        ({"in_domain": b"\x01\x01"}, "in_domain has 2 rows but constraints_ok has 1"),
        ({"mean": [[1.0, 2.0, 3.0]]}, "must be bytes"),
        ({"output_names": None}, "field 'output_names' = None"),
        ({"model_id": 7}, "field 'model_id' = 7"),
        ({"schema_version": 3}, "field 'schema_version' = 3"),
    ):
        with pytest.raises(MessageError, match="surrogate reply") as info:
            sg.decode_reply(msgpack.packb({**good, **change}))
        assert expected in str(info.value)
