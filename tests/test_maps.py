"""`nearsub maps`: the colour maps of thesis section 4.5 from a model file ."""

import numpy as np
import pytest

from nearsub.common.surrogate.domain import constraint_values, constraints_ok
from nearsub.common.surrogate.maps import THESIS_MAPS, evaluate_map, mid_window_r_lat, slice_grid
from nearsub.common.surrogate.model import load_surrogate
from nearsub.tools import map_figures
from nearsub.tools.cli import main
from nearsub.tools.commands.surrogate import write_analytic_model

pytestmark = pytest.mark.timeout(180)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def shipped():
    return load_surrogate()


def test_mid_window_r_lat_satisfies_4_4_and_4_5_for_every_uuv_size():
    d, ld = np.meshgrid(np.linspace(5, 50, 46), np.linspace(4.3, 13, 30))
    rows = np.column_stack(
        [
            np.zeros(d.size),
            mid_window_r_lat(d, ld).ravel(),
            np.full(d.size, 3.5),
            np.zeros(d.size),
            d.ravel(),
            ld.ravel(),
        ]
    )
    assert np.all(constraint_values(rows)[:, :2] >= 0.0)  # (4.4) and (4.5)
    # Why the maps need it: the thesis's R_lat = 0.08 at D_sub/D_uuv = 20 breaks (4.5)
    # (docs/design.md, "Thesis errata" 7).
    assert not constraints_ok([0.0, 0.08, 3.5, 0.0, 20.0, 8.0])[0]


def test_a_map_holds_the_thesis_values_and_is_blank_exactly_where_the_constraints_fail(shipped):
    panel = THESIS_MAPS["fig4-8"][0]  # X' over L/D_uuv and D_sub/D_uuv; (4.6) and (4.7) cut corners
    X, xs, ys = slice_grid(panel, nx=25, ny=19)
    assert np.all(X[..., 0] == 0.0) and np.all(X[..., 2] == 3.5) and np.all(X[..., 3] == 0.0)
    assert np.array_equal(X[0, :, 5], xs) and np.array_equal(X[:, 0, 4], ys)
    data = evaluate_map(shipped.model, panel, nx=25, ny=19)
    feasible = constraints_ok(X.reshape(-1, 6)).reshape(X.shape[:2])
    assert 0 < feasible.sum() < feasible.size
    assert np.array_equal(np.isfinite(data["values"]), feasible)


def test_the_shipped_model_shows_the_section_4_5_pattern(shipped):
    # Figure 4-4's UUV (D_sub/D_uuv = 10, L/D = 8) at 3.5 kn, psi = 0, mid-gap R_lat = 0.075.
    def at(r_long):
        return shipped.predict([r_long, 0.075, 3.5, 0.0, 10.0, 8.0]).mean[0]

    for r_long in (0.3, 0.4, 0.45):  # near the bow: the UUV's bow turned away
        assert at(r_long)[2] > 0.0
    assert at(0.45)[1] > 0.0  # pushed away at the submarine's nose
    for r_long in (-0.3, -0.4, -0.5):  # near the stern: its bow turned toward the submarine
        assert at(r_long)[2] < 0.0
    assert at(-0.3)[1] < 0.0 and at(-0.4)[1] < 0.0  # pulled in over the afterbody
    assert at(-0.4)[0] > 0.0 and at(0.0)[0] < 0.0  # surge positive near R_long = -0.4 only


def test_a_figure_is_a_png_with_its_panels(shipped, tmp_path):
    path = map_figures.plot_figure(shipped, "fig4-9", tmp_path, nx=21, ny=15)
    assert path == tmp_path / "fig4-9.png" and path.read_bytes().startswith(PNG_MAGIC)


@pytest.mark.slow  # every thesis map of the shipped model: minutes; one map is drawn above
def test_maps_writes_every_figure_for_the_shipped_model(tmp_path, capsys):
    assert main(["maps", "--out", str(tmp_path)]) == 0
    names = sorted(p.name for p in tmp_path.glob("*.png"))
    assert names == sorted(f"{name}.png" for name in THESIS_MAPS)
    assert "wrote" in capsys.readouterr().out


def test_maps_skips_the_lf_comparisons_of_a_single_fidelity_model(tmp_path, capsys, monkeypatch):
    model = write_analytic_model(tmp_path / "analytic.npz", n=30)
    drawn = []
    monkeypatch.setattr(
        map_figures, "plot_figure", lambda surrogate, name, out_dir: drawn.append(name) or out_dir / name
    )
    assert main(["maps", str(model), "--out", str(tmp_path / "maps")]) == 0
    assert drawn == ["fig4-4", "fig4-5", "fig4-7", "fig4-8"]
    out = capsys.readouterr().out
    assert all(f"skipped {name}" in out for name in ("fig4-9", "fig4-10", "fig4-11"))


def test_maps_reports_a_bad_model_file(tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a model")
    assert main(["maps", str(bad), "--out", str(tmp_path)]) == 2
    assert "bad.npz" in capsys.readouterr().err
