"""Uncertainty-aware envelopes: cells flown under posterior samples of the surrogate's residual
(small grids and short runs; the full maps are docs/envelopes/uncertainty)."""

import csv
import json
import math

import numpy as np
import pytest

from conftest import nearsub
from nearsub.common.analysis import envelope as env
from nearsub.common.analysis.batch import OUTCOMES, run_batch
from nearsub.common.physics import waves

# Cells next to the hull, where the residual acts (the SDV's window is near R_lat 0.06).
SMALL = env.EnvelopeConfig(vehicle="sdv", grid=(5, 3), r_long=(-0.4, 0.4), r_lat=(0.055, 0.07), duration=8.0)


def _batch(config, **seam):
    x, y = env.cell_positions(config)
    starts, ends, feasible = env.starts_and_tracks(config, x, y)
    surrogate = env.cached_surrogate(config.model)
    return run_batch(env.cell_mission(config, 0.0, 0.0), starts, ends, surrogate, feasible, **seam), surrogate


@pytest.mark.parametrize("behaviour", ["waypoints", "nuv_compensation"])
def test_the_mean_through_the_seam_is_the_deterministic_envelope(behaviour):
    config = SMALL.model_copy(update={"behaviour": behaviour})
    plain, surrogate = _batch(config)
    seen = []

    def mean(X, uuvs):
        seen.append(len(uuvs))
        return surrogate.discrepancy(X, return_std=False)[0]

    through, _ = _batch(config, delta=mean, time_offset=np.zeros(len(plain.outcome)))
    assert sum(seen) > 0  # the seam was used
    for field in ("outcome", "closest", "max_cross_track", "final", "steps"):
        np.testing.assert_array_equal(getattr(through, field), getattr(plain, field))


def test_probabilities_quantiles_and_reproducibility():
    sampling = env.Sampling(4, seed=3)
    found = env.compute_sampled(SMALL, sampling)
    p = found.probabilities()
    assert p.shape == (15, len(OUTCOMES)) and ((p >= 0) & (p <= 1)).all()
    np.testing.assert_allclose(p.sum(axis=1), 1.0)
    q = found.closest_quantiles()
    feasible = p[:, OUTCOMES.index("infeasible")] == 0
    assert (np.diff(q[feasible], axis=1) >= 0).all()
    again = env.compute_sampled(SMALL, sampling)
    np.testing.assert_array_equal(again.result.final, found.result.final)
    other = env.compute_sampled(SMALL, env.Sampling(4, seed=4))
    assert not np.array_equal(other.result.final, found.result.final)  # other fields, other runs
    # sample k flies its own field: its rows differ from sample 0's
    final = found.result.final.reshape(4, 15, 6)[:, feasible]
    assert not np.array_equal(final[1], final[0])
    summary = json.loads(json.dumps(found.summary()))
    assert summary["sampling"]["samples"] == 4 and math.isclose(sum(summary["expected_fractions"].values()), 1.0)


def test_a_split_of_the_samples_flies_the_same_fields():
    """Row-by-row arithmetic: samples 2..3 alone give the rows they give within all four (what a
    Dask task of `sampled_envelope` computes)."""
    sampling = env.Sampling(4, seed=1)
    whole = env.compute_sampled(SMALL, sampling)
    part = env.compute_sampled(SMALL, sampling, members=[2, 3])
    np.testing.assert_array_equal(part.result.final, whole.result.final[30:])
    np.testing.assert_array_equal(part.result.closest, whole.result.closest[30:])


@pytest.mark.timeout(240)
def test_dask_equals_the_single_process_run():
    pytest.importorskip("distributed")
    config = SMALL.model_copy(update={"duration": 4.0})
    sampling = env.Sampling(3, seed=2)
    here = env.sampled_envelope(config, sampling)
    there = env.sampled_envelope(config, sampling, workers=2)
    for field in ("outcome", "closest", "final", "steps"):
        np.testing.assert_array_equal(getattr(there.result, field), getattr(here.result, field))


def test_random_wave_phase_is_a_clock_offset():
    config = SMALL.model_copy(update={"sea_state": 6, "depth": 50.0})
    sampling = env.Sampling(5, seed=0, wave_phase="random")
    offsets = env.wave_time_offsets(config, sampling)
    assert env.wave_time_offsets(config, env.Sampling(5)) is None
    assert env.wave_time_offsets(SMALL, sampling) is None  # calm water: no phase
    state = waves.sea_state(6)
    x, t = np.array([-20.0, 5.0]), 3.0
    phase = lambda x, t: state.wavenumber * (x + config.u_sub * t) - state.omega * t  # noqa: E731
    shifted = np.array([phase(x, t + t0) - phase(x, t) for t0 in offsets])
    drawn = np.random.default_rng([0, 1]).uniform(0.0, 2.0 * math.pi, 5)
    np.testing.assert_allclose(
        np.mod(shifted, 2 * math.pi), np.broadcast_to(np.mod(-drawn, 2 * math.pi)[:, None], (5, 2))
    )


def test_cli_writes_probabilities_and_rejects_bad_samples(tmp_path):
    out = tmp_path / "u.png"
    done = nearsub(
        "envelope",
        "--vehicle",
        "sdv",
        "--grid",
        "3x2",
        "--r-lat",
        "0.055,0.07",
        "--duration",
        "3",
        "--samples",
        "2",
        "--wave-phase",
        "random",
        "--sea-state",
        "5",
        "-o",
        str(out),
        timeout=180,
    )
    assert done.returncode == 0, done.stderr
    summary = json.loads(out.with_suffix(".json").read_text())
    assert summary["sampling"] == {"samples": 2, "seed": 0, "wave_phase": "random", "features": 256}
    rows = list(csv.DictReader(out.with_suffix(".csv").open()))
    assert len(rows) == 6 and {"p_collision", "closest_q05", "closest_q95"} <= set(rows[0])
    assert out.stat().st_size > 0
    for bad in (
        ["--samples", "0"],
        ["--samples", "-3"],
        ["--samples", "2", "--sample-seed", "-1"],
        ["--wave-phase", "random"],
    ):
        done = nearsub("envelope", "--vehicle", "sdv", *bad)
        # One line naming the option: the tool's own, or argparse's after its usage lines.
        last = done.stderr.strip().splitlines()[-1]
        assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
        assert bad[-2] in last or bad[0] in last, done.stderr
