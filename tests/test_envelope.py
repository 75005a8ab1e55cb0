"""Operating envelopes: the cells, their outcomes, the CLI's files, the thesis figure set and the
Dask scale-out (small grids and short runs; the full figures are `nearsub envelope --thesis-figures`)."""

import csv
import json
import sys

import numpy as np
import pytest

from conftest import nearsub
from nearsub.common.analysis import envelope as env
from nearsub.common.analysis.batch import OUTCOMES
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.physics import proximity as events
from nearsub.common.physics.hull import L_SUB, R_SUB
from nearsub.common.physics.vehicles import get_vehicle

SMALL = env.EnvelopeConfig(vehicle="sdv", grid=(6, 4), r_long=(-0.5, 0.5), r_lat=(0.05, 0.075), duration=8.0)


def test_grid_cells_and_starts():
    r_long, r_lat = env.grid_axes(SMALL)
    np.testing.assert_allclose(r_long[[0, -1]], [-0.5, 0.5])
    np.testing.assert_allclose(r_lat[[0, -1]], [0.05, 0.075])
    x, y = env.cell_positions(SMALL)
    assert x.shape == (24,)
    assert (x[1], y[1]) == pytest.approx((-0.5 * L_SUB, r_lat[1] * L_SUB))  # R_long-major order
    starts, ends, feasible = env.starts_and_tracks(SMALL, x, y)
    np.testing.assert_allclose(starts[:, 0], 1.5)  # U_UUV = U_sub + U_ot, heading 0
    np.testing.assert_allclose(starts[:, [1, 2, 5]], 0.0)
    np.testing.assert_allclose(ends[:, 1], y)  # track-line parallel to the axis through the start
    # The first row lies inside the middle body (4.4 m < R_sub): infeasible there, feasible near the ends.
    sdv = get_vehicle("sdv")
    touching = events.closest_distance(x, y, 0.0, sdv.length, sdv.diameter) <= 0
    assert feasible.tolist() == (~touching).tolist()
    assert not feasible[[4 * k for k in (2, 3)]].any() and feasible[0]
    assert y[0] < R_SUB


def test_d_lead_and_gamma_reach_the_mission():
    config = env.EnvelopeConfig(vehicle="remus100", behaviour="nuv_compensation", d_lead=5.0, gamma=2.5, u_ot=0.25)
    mission = env.cell_mission(config, 10.0, 6.0)
    leg = mission.apps.helm.legs[0]
    assert leg.lead == pytest.approx(5.0 * 1.33) and leg.speed == pytest.approx(1.75)
    assert mission.apps.helm.gamma == 2.5 and mission.apps.helm.behaviour == "nuv_compensation"
    assert (mission.start.x, mission.start.y, mission.start.speed) == (10.0, 6.0, 1.75)
    assert mission.environment.submarine and mission.dt == 0.1 and mission.max_steps == 1200


def test_mission_file_of_a_cell_loads_back(tmp_path):
    config = env.EnvelopeConfig(vehicle="nps_auv_ii", sea_state=5, gamma=1.5, behaviour="nuv_compensation")
    data = env.mission_data(config, -20.5, 5.9, name="cell")
    path = tmp_path / "cell.toml"
    path.write_text(env.mission_toml(data))
    assert load_mission(path) == env.cell_mission(config, -20.5, 5.9, name="cell")


@pytest.mark.parametrize("behaviour", ["waypoints", "nuv_compensation", "modified_waypoints"])
def test_cells_end_as_their_missions_do(behaviour):
    """A few cells of an envelope against the cores run one mission at a time (in-process; the
    multi-process launcher is tests/test_envelope_pipeline.py)."""
    config = SMALL.model_copy(update={"behaviour": behaviour, "duration": 6.0})
    found = env.compute_envelope(config)
    x, y = env.cell_positions(config)
    for k in np.flatnonzero(found.result.outcome != OUTCOMES.index("infeasible"))[::5]:
        single = run_mission(env.cell_mission(config, x[k], y[k]), env.cached_surrogate(""))
        last = single.topic("state")[-1]
        np.testing.assert_allclose(
            found.result.final[k], [last.u, last.v, last.r, last.x, last.y, last.psi], rtol=0, atol=1e-9
        )
        assert (single.outcome == "collision") == (OUTCOMES[found.result.outcome[k]] == "collision")


def test_outcomes_fractions_and_summary():
    found = env.compute_envelope(SMALL)
    summary = found.summary()
    assert summary["cells"] == 24 and sum(summary["counts"].values()) == 24
    assert summary["feasible_cells"] == 24 - summary["counts"]["infeasible"]
    assert sum(summary["fractions"].values()) == pytest.approx(1.0)
    grid = np.asarray(summary["outcome"])
    assert grid.shape == (6, 4) and grid.ravel().tolist() == found.result.outcome.tolist()
    assert summary["vehicle_steps"] == int(found.result.steps.sum()) > 0
    json.dumps(summary)  # JSON-able
    rows = found.cell_rows()
    assert len(rows) == 24 and {row["outcome"] for row in rows} <= set(OUTCOMES)


def test_classification_priority():
    """Collision beats close call beats large stray; an infeasible cell is nothing else."""
    rows = env.compute_envelope(SMALL.model_copy(update={"duration": 20.0})).cell_rows()
    for row in rows:
        if row["outcome"] == "large_stray":
            assert row["max_cross_track"] > events.STRAY_LIMIT
        if row["outcome"] == "safe":
            assert row["max_cross_track"] <= events.STRAY_LIMIT and row["closest"] > 0
        if row["outcome"] == "infeasible":
            assert row["steps"] == 0


def test_cli_writes_png_csv_and_json(tmp_path):
    out = tmp_path / "env" / "sdv.png"
    grid = ["--grid", "5x3", "--duration", "4", "--r-lat", "0.06,0.08"]
    done = nearsub("envelope", "--vehicle", "large", *grid, "-o", str(out), "--json", timeout=120)
    assert done.returncode == 0, done.stderr
    printed = json.loads(done.stdout.splitlines()[-1])
    assert printed["cells"] == 15 and set(printed["fractions"]) == set(OUTCOMES[:-1])
    assert out.stat().st_size > 10_000
    with out.with_suffix(".csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 15 and {"x", "y", "outcome", "closest", "max_cross_track"} <= set(rows[0])
    summary = env.load_summary(out.with_suffix(".json"))
    assert summary["config"]["vehicle"] == "sdv" and summary["config"]["grid"] == [5, 3]

    compared = tmp_path / "compare.png"
    json_path = str(out.with_suffix(".json"))
    done = nearsub("envelope", "--compare", json_path, json_path, "-o", str(compared))
    assert done.returncode == 0, done.stderr
    assert compared.stat().st_size > 10_000
    bad = nearsub("envelope", "--compare", json_path, str(out.with_suffix(".csv")))
    assert bad.returncode == 2 and "envelope" in bad.stderr


def test_cli_options_make_a_sweep(tmp_path):
    done = nearsub(
        "envelope", "--vehicle", "small", "--sea-state", "0", "5", "--d-lead", "1L", "2.66m",
        "--grid", "3x2", "--duration", "2", "-o", str(tmp_path), timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    names = sorted(p.name for p in tmp_path.glob("*.json"))
    assert names == [
        "remus100_waypoints_dlead1L_ss0-50m.json",
        "remus100_waypoints_dlead1L_ss5-50m.json",
        "remus100_waypoints_dlead2L_ss0-50m.json",
        "remus100_waypoints_dlead2L_ss5-50m.json",
    ]


def test_thesis_figure_set():
    figures = env.thesis_figures()
    assert [f.number for f in figures] == ["5-10", "5-11", "5-12", "5-13", "5-14", "6-7", "6-8", "6-9", "6-10", "6-11"]
    by_number = {f.number: f for f in figures}
    assert [c.vehicle for _, c in by_number["5-10"].panels] == ["remus100", "nps_auv_ii", "sdv"]
    assert [c.d_lead for _, c in by_number["5-11"].panels] == [1.0, 3.0, 5.0]
    assert [(c.sea_state, c.depth) for _, c in by_number["5-13"].panels] == [(6, 90.0)] * 3
    assert [c.gamma for _, c in by_number["6-8"].panels] == [1.0, 5.0, 10.0]
    assert [c.behaviour for _, c in by_number["6-11"].panels] == ["waypoints", "nuv_compensation"] * 3
    assert all(c.u_sub == 1.5 and c.u_ot == 0 for f in figures for _, c in f.panels)
    assert len(env.unique_configs(figures)) == 29  # figures share their uncompensated panels


@pytest.mark.slow  # every figure: 29 configurations; the default run draws one figure and reuses another's
@pytest.mark.timeout(300)
def test_thesis_figures_command(tmp_path):
    done = nearsub("envelope", "--thesis-figures", "--grid", "3x2", "--duration", "1", "-o", str(tmp_path), timeout=280)
    assert done.returncode == 0, done.stderr
    pngs = sorted(p.name for p in tmp_path.glob("figure-*.png"))
    assert len(pngs) == 10 and "figure-6-11.png" in pngs
    assert len(list((tmp_path / "data").glob("*.json"))) == 29
    table = (tmp_path / "fractions.md").read_text().splitlines()
    assert len(table) == 2 + 3 * 5 + 6 + 3 + 6 * 3  # header and 42 panels
    assert json.loads((tmp_path / "timing.json").read_text())["configurations"] == 29


@pytest.fixture
def local_cluster():
    """A two-worker Dask cluster on loopback, closed at teardown."""
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None, processes=True
    )
    yield cluster
    cluster.close()


SWEEP = [
    SMALL.model_copy(update={"vehicle": v, "sea_state": s, "duration": 5.0})
    for v in ("remus100", "sdv")
    for s in (0, 6)
]


@pytest.mark.timeout(240)
def test_dask_sweep_equals_the_single_process_run(local_cluster):
    here = env.sweep(SWEEP)
    there = env.sweep(SWEEP, scheduler=local_cluster.scheduler_address)
    for a, b in zip(here, there, strict=True):
        assert a.config == b.config
        np.testing.assert_array_equal(a.result.outcome, b.result.outcome)
        np.testing.assert_array_equal(a.result.final, b.result.final)
        np.testing.assert_array_equal(a.result.closest, b.result.closest)


@pytest.mark.timeout(240)
def test_workers_option_starts_and_closes_a_local_cluster():
    seen = []
    results = env.sweep(SWEEP[:2], workers=2, on_done=lambda index, found: seen.append(index))
    assert sorted(seen) == [0, 1] and [r.config for r in results] == SWEEP[:2]
    np.testing.assert_array_equal(results[1].result.final, env.compute_envelope(SWEEP[1]).result.final)
    assert "distributed" in sys.modules


def test_thesis_figures_subset_reuse_and_unknown_figure(tmp_path):
    """--figure draws those figures only; --reuse flies only the configurations missing from
    the folder; an unknown figure is refused."""
    small = ("--grid", "3x2", "--duration", "1", "-o", str(tmp_path))
    done = nearsub("envelope", "--thesis-figures", "--figure", "5-11", *small)
    assert done.returncode == 0, done.stderr
    assert [p.name for p in tmp_path.glob("figure-*.png")] == ["figure-5-11.png"]
    assert len(list((tmp_path / "data").glob("*.json"))) == 3
    bad = nearsub("envelope", "--thesis-figures", "--figure", "5-99", "-o", str(tmp_path))
    assert bad.returncode == 2 and "5-99" in bad.stderr
    deleted = tmp_path / "data" / "remus100_waypoints_dlead1L_ss0-50m.json"
    deleted.unlink()
    stored = {p.name: p.read_text() for p in (tmp_path / "data").glob("*.json")}
    done = nearsub("envelope", "--thesis-figures", "--reuse", "--figure", "5-11", "6-8", *small)
    assert done.returncode == 0, done.stderr
    timing = json.loads((tmp_path / "timing.json").read_text())
    assert (timing["configurations"], timing["reused"]) == (4, 2)  # 6-8's three gammas and the deleted one
    now = {p.name: p.read_text() for p in (tmp_path / "data").glob("*.json")}
    assert len(now) == 6 and all(now[name] == text for name, text in stored.items())
    assert sorted(p.name for p in tmp_path.glob("figure-*.png")) == ["figure-5-11.png", "figure-6-8.png"]
    other_grid = nearsub(
        "envelope",
        "--thesis-figures",
        "--reuse",
        "--figure",
        "5-11",
        "--grid",
        "2x2",
        "--duration",
        "1",
        "-o",
        str(tmp_path),
    )
    assert other_grid.returncode == 0 and json.loads((tmp_path / "timing.json").read_text())["reused"] == 0


def test_bench_envelope_prints_its_figures():
    done = nearsub(
        "bench", "envelope", "--grid", "4x2", "--duration", "2", "--repeats", "1", "--sample", "2", "--skip-thesis",
        "--json", timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["cells"] == 8 and result["vehicle_steps"] > 0 and result["vehicle_steps_per_second"] > 0
    assert result["speed_up"] > 0 and result["one_by_one_sample_cells"] == 2 and "thesis_figures" not in result


def test_cell_mission_option_writes_a_launchable_mission(tmp_path):
    path = tmp_path / "cell.toml"
    done = nearsub("envelope", "--vehicle", "sdv", "--sea-state", "5", "--cell-mission=-0.3,0.065", "-o", str(path))
    assert done.returncode == 0, done.stderr
    config = env.EnvelopeConfig(vehicle="sdv", sea_state=5)
    assert load_mission(path) == env.cell_mission(config, -0.3 * L_SUB, 0.065 * L_SUB, name="envelope_cell")


@pytest.mark.parametrize("vehicle", ["remus100", "nps_auv_ii", "sdv"])
def test_drawn_surrogate_window_is_where_the_blend_weight_is_positive(vehicle):
    """The dashed box of the figures is where the residual GP is trained; no box for a hull that fails
    (4.6) or (4.7) (the NPS AUV II fails (4.6), so the residual GP never corrects the LF on it)."""
    from nearsub.common.surrogate.interaction import interaction_at

    r_lat = np.linspace(0.05, 0.12, 701)
    states = np.zeros((len(r_lat), 6))
    states[:, 0], states[:, 4] = 1.5, r_lat * L_SUB  # heading 0 at R_long 0, U_sub 1.5 m/s
    weight = interaction_at(
        env.cached_surrogate(""), states, get_vehicle(vehicle), 1025.0, "replace"
    ).interaction.weight
    window = env.surrogate_window(vehicle)
    if vehicle == "nps_auv_ii":
        assert window is None and not weight.any()
        return
    low, high = window
    acting = r_lat[weight > 0]
    assert acting.size and low <= acting.min() and acting.max() <= high
    assert acting.min() - low < 0.002 and high - acting.max() < 0.002  # the ramps are about 5 cm (0.0006)


def _hull_patch(ax):
    """The filled submarine outline: the patch whose vertices reach both tips."""
    return max(ax.patches, key=lambda p: np.ptp(p.get_xy()[:, 0]))


def test_the_map_is_in_metres_at_equal_aspect_with_the_hull_to_scale_and_says_what_a_cell_is():
    """Read back from the matplotlib objects: x and y in metres on the same scale, the hull's
    outline spanning the SUBOFF hull's length and radius, the cells where their starts are, and a
    title line naming one cell's start, speed, duration and behaviour."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from nearsub.common.physics.hull import SUB_BOW_X, SUB_STERN_X
    from nearsub.tools.commands.envelope import collision_probability_figure, draw_envelope

    summary = env.compute_envelope(SMALL).summary()
    assert summary["x_m"] == pytest.approx((np.asarray(summary["r_long"]) * L_SUB).tolist())
    assert summary["y_m"] == pytest.approx((np.asarray(summary["r_lat"]) * L_SUB).tolist())
    fig, ax = plt.subplots()
    draw_envelope(ax, summary)
    sampled = env.compute_sampled(SMALL, env.Sampling(2, seed=0)).summary()
    sampled_fig = collision_probability_figure(sampled)
    for axes in (ax, sampled_fig.axes[0]):
        assert axes.get_aspect() == 1.0  # one metre along x is one metre along y
        assert "[m]" in axes.get_xlabel() and "[m]" in axes.get_ylabel()
        hull = _hull_patch(axes).get_xy()
        assert hull[:, 0].min() == pytest.approx(SUB_STERN_X, abs=1e-6)
        assert hull[:, 0].max() == pytest.approx(SUB_BOW_X, abs=1e-6)
        assert hull[:, 1].max() == pytest.approx(R_SUB, abs=1e-3)
        x_lo, x_hi = axes.get_xlim()
        half_cell = 0.5 * (summary["x_m"][1] - summary["x_m"][0])
        assert (x_lo, x_hi) == pytest.approx((summary["x_m"][0] - half_cell, summary["x_m"][-1] + half_cell))
        y_lo, y_hi = axes.get_ylim()
        assert y_lo == 0.0 and y_hi > summary["y_m"][-1]  # from the axis: the whole half-hull shows
        mesh = axes.collections[0].get_coordinates()  # the cells' corners
        assert mesh[..., 0].min() == pytest.approx(x_lo) and mesh[..., 1].max() == pytest.approx(y_hi)
        title = axes.get_title()
        assert "one cell: a sdv starts at the cell's centre, heading 0 (along the submarine) at 1.5 m/s" in title
        assert "flies 8 s (waypoints, d_lead 3 L)" in title
    plt.close("all")


def test_redraw_draws_a_stored_envelope_again_from_its_json_alone(tmp_path, capsys):
    from nearsub.tools.cli import main

    stored = tmp_path / "small.json"
    env.save_summary(env.compute_envelope(SMALL).summary(), stored)
    out = tmp_path / "again.png"
    assert main(["envelope", "--redraw", str(stored), "-o", str(out)]) == 0
    assert out.stat().st_size > 10_000 and f"wrote {out}" in capsys.readouterr().out
    other = tmp_path / "other.json"
    other.write_text('{"config": {}}')
    assert main(["envelope", "--redraw", str(other), "-o", str(tmp_path / "x.png")]) == 2
    assert "--redraw" in capsys.readouterr().err and not (tmp_path / "x.png").exists()
