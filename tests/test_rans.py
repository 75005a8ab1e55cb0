"""The RANS fidelity (common/hydro/rans*.py, `nearsub cfd`; docs/hydro/rans/README.md).

Unit tests need no OpenFOAM. `test_smoke_case` meshes and solves a coarse SUBOFF on 2 cores end to
end (about 15-40 s); the full validation (hours) runs with `pytest -m cfd`.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import nearsub
from nearsub.common.analysis import rans_comparison
from nearsub.common.hydro import rans, rans_campaign
from nearsub.common.hydro.rans_geometry import Body, enclosed_volume, open_edges, read_stl, write_stl
from nearsub.common.physics.hull import SUBOFF_SCALE, suboff_properties

DATA = Path(__file__).parent / "data" / "rans"


def _foam(path):
    from foamlib import FoamFile

    return FoamFile(path)


# --- geometry ------------------------------------------------------------------------------------


def test_suboff_stl_is_closed_and_matches_the_profile(tmp_path):
    body = Body("suboff", "suboff-model", rans.SUBOFF_MODEL_LENGTH, rans.SUBOFF_MODEL_DIAMETER)
    triangles = body.triangles()
    assert open_edges(triangles) == 0
    volume = suboff_properties().volume / SUBOFF_SCALE**3  # the profile's own volume at model scale
    assert enclosed_volume(triangles) == pytest.approx(volume, rel=2e-3)
    lo, hi = triangles.reshape(-1, 3).min(axis=0), triangles.reshape(-1, 3).max(axis=0)
    assert hi[0] - lo[0] == pytest.approx(4.3561, rel=1e-4)  # Groves, Huang & Chang (1989)
    assert hi[1] - lo[1] == pytest.approx(0.508, rel=2e-3)
    write_stl(tmp_path / "s.stl", triangles, "suboff")
    assert np.allclose(read_stl(tmp_path / "s.stl"), triangles, atol=1e-6)
    # No vertex on a symmetry plane (snappyHexMesh misses intersections in a facet's plane).
    assert np.min(np.abs(triangles[..., 2][np.abs(triangles[..., 2]) > 0])) > 1e-4


def test_placed_uuv_ends_follow_its_heading():
    body = Body("uuv", "explorer", 4.0, 0.5, x=10.0, y=7.0, psi=math.radians(5.0))
    bow, stern = body.ends()
    axis = (bow - stern) / np.linalg.norm(bow - stern)
    assert axis[:2] == pytest.approx([math.cos(math.radians(5)), math.sin(math.radians(5))], abs=1e-9)
    assert np.linalg.norm(bow - stern) == pytest.approx(4.0, rel=1e-6)
    assert open_edges(body.triangles(80, 24)) == 0


# --- case dictionaries ---------------------------------------------------------------------------


def test_suboff_case_dictionaries(tmp_path):
    spec = rans.suboff_case(0.0, "coarse")
    folder = rans.write_case(spec, tmp_path / "c", cores=2)
    control = _foam(folder / "system/controlDict")
    forces = control["functions"]["forces_suboff"]
    assert forces["type"] == "forces" and list(forces["patches"]) == ["suboff"]
    assert forces["rhoInf"] == pytest.approx(997.0)  # thesis section 3.2
    assert control["application"] == "simpleFoam"
    blocks = _foam(folder / "system/blockMeshDict")
    patches = [p[0] for p in blocks["boundary"]]
    assert "symmetryY" in patches and "symmetryZ" in patches  # quarter domain at zero drift
    assert _foam(folder / "system/decomposeParDict")["method"] == "hierarchical"
    layers = _foam(folder / "system/snappyHexMeshDict")["addLayersControls"]
    assert layers["firstLayerThickness"] == pytest.approx(rans.first_layer_thickness(spec), rel=1e-3)
    assert layers["layers"]["suboff"]["nSurfaceLayers"] == rans.LAYERS
    turbulence = _foam(folder / "constant/turbulenceProperties")
    assert turbulence["RAS"]["RASModel"] == "kOmegaSST"
    u = _foam(folder / "0.orig/U")
    assert np.allclose(u["internalField"], [-3.05, 0.0, 0.0])  # uniform start, stream -x
    assert _foam(folder / "0.orig/nut")["boundaryField"]["suboff"]["type"] == "nutkWallFunction"
    assert rans.load_spec(folder) == spec


def test_drift_case_is_a_half_domain_with_the_chosen_wall_function(tmp_path):
    spec = rans.suboff_case(4.07, "medium", "spalding", 30.0)
    assert not spec.quarter and spec.case_id == "suboff-psi4.07-medium-spalding-yp30"
    folder = rans.write_case(spec, tmp_path / "d", cores=1)
    patches = [p[0] for p in _foam(folder / "system/blockMeshDict")["boundary"]]
    assert "symmetryY" not in patches and "sideNear" in patches
    assert _foam(folder / "0.orig/nut")["boundaryField"]["suboff"]["type"] == "nutUSpaldingWallFunction"
    # A smaller y+ gives a thinner first layer.
    assert rans.first_layer_thickness(spec) == pytest.approx(rans.first_layer_thickness(rans.suboff_case(4.07)) * 0.6)


def test_a_first_cell_below_the_log_layer_gets_the_thesis_prism_layers(tmp_path):
    """Below y+ 30 the measured body's layers grow by 1.2 until they span Prandtl's boundary-layer
    thickness (thesis section 3.3.3.3, (3.10)), and only the layer addition drops the checks that
    thin cells fail by their shape; at y+ 30 and above the case is written as before."""
    spec = rans.suboff_case(0.0, "medium", "spalding", 1.0)
    shm = _foam(rans.write_case(spec, tmp_path / "r") / "system/snappyHexMeshDict")
    controls = shm["addLayersControls"]
    count, expansion = rans.boundary_layers(spec)
    assert controls["layers"]["suboff"]["nSurfaceLayers"] == count and 30 <= count <= 45
    assert controls["layers"]["suboff"]["expansionRatio"] == pytest.approx(1.2) == expansion
    reynolds = 3.05 * 4.3561 / (8.899e-4 / 997)  # thesis table 3.1's tow tank
    delta = 0.16 * 4.3561 / reynolds ** (1 / 7)  # thesis (3.10): 66 mm
    stack = rans.first_layer_thickness(spec) * (expansion**count - 1) / (expansion - 1)
    assert stack == pytest.approx(delta, rel=0.1)  # within half a growth step
    assert controls["nRelaxedIter"] == 0
    quality = shm["meshQualityControls"]
    assert quality["minDeterminant"] == pytest.approx(0.001) and quality["minTwist"] == pytest.approx(0.02)
    relaxed = quality["relaxed"]
    assert relaxed["minDeterminant"] <= 0 and relaxed["minTwist"] < -1 and relaxed["minTetQuality"] < -1e29
    assert relaxed["maxNonOrtho"] == 75  # OpenFOAM's meshQualityDict.cfg
    assert "minFaceWeight" not in relaxed and "maxInternalSkewness" not in relaxed  # the layers keep the rest
    # A thicker first cell needs fewer layers to reach the same outer cells.
    assert rans.boundary_layers(rans.suboff_case(0.0, "medium", "spalding", 10.0))[0] < count
    # y+ 30: the wall-function recipe, unchanged.
    wall = _foam(
        rans.write_case(rans.suboff_case(0.0, "medium", "spalding", 30.0), tmp_path / "w") / "system/snappyHexMeshDict"
    )
    assert wall["addLayersControls"]["layers"]["suboff"]["nSurfaceLayers"] == rans.LAYERS
    assert wall["addLayersControls"]["expansionRatio"] == pytest.approx(rans.LAYER_EXPANSION)
    assert "relaxed" not in wall["meshQualityControls"] and "nRelaxedIter" not in wall["addLayersControls"]
    # In a two-body case only the measured UUV resolves its sublayer; the submarine keeps y+ 300.
    two = rans.two_body_case([0.2, 0.08, 3.5, 2.0, 20.0, 8.0], "coarse", "spalding", 1.0)
    layers = _foam(rans.write_case(two, tmp_path / "t") / "system/snappyHexMeshDict")["addLayersControls"]["layers"]
    assert layers["uuv"]["nSurfaceLayers"] == rans.boundary_layers(two)[0] > rans.LAYERS
    assert layers["submarine"]["nSurfaceLayers"] == rans.LAYERS
    assert layers["submarine"]["expansionRatio"] == pytest.approx(rans.LAYER_EXPANSION)


def test_mesh_levels_refine_by_a_constant_ratio():
    sizes = [rans.domain(rans.suboff_case(0.0, lv)).background for lv in ("coarse", "medium", "fine")]
    assert sizes[0] / sizes[1] == pytest.approx(math.sqrt(2)) and sizes[1] / sizes[2] == pytest.approx(math.sqrt(2))
    levels = {rans.domain(rans.suboff_case(0.0, lv)).surface_levels for lv in ("coarse", "medium", "fine")}
    assert len(levels) == 1  # same levels, so every cell is refined by the same ratio


def test_two_body_case_places_the_uuv_from_the_row(tmp_path):
    spec = rans.two_body_case([0.2, 0.08, 3.5, 2.0, 20.0, 8.0], "coarse")
    uuv, sub = spec.bodies
    assert uuv.x == pytest.approx(0.2 * 88.86, rel=1e-3) and uuv.y == pytest.approx(0.08 * 88.86, rel=1e-3)
    assert uuv.psi == pytest.approx(math.radians(2.0)) and uuv.length == pytest.approx(8 * uuv.diameter)
    assert spec.rho == 1025.0 and spec.speed == pytest.approx(3.5 * 1852 / 3600)
    folder = rans.write_case(spec, tmp_path / "t")
    functions = _foam(folder / "system/controlDict")["functions"]
    assert np.allclose(functions["forces_uuv"]["CofR"], [uuv.x, uuv.y, 0.0], atol=1e-6)
    assert "forces_submarine" in functions
    layers = _foam(folder / "system/snappyHexMeshDict")["addLayersControls"]["layers"]
    assert layers["uuv"]["firstLayerThickness"] == pytest.approx(rans.first_layer_thickness(spec), rel=1e-3)
    assert layers["submarine"]["firstLayerThickness"] > 5 * layers["uuv"]["firstLayerThickness"]  # y+ 300
    # The UUV is thinner than a background cell: a shell at its surface level carries it there.
    shells = _foam(folder / "system/snappyHexMeshDict")["castellatedMeshControls"]["refinementRegions"]
    assert shells["uuv"]["levels"][0][1] == rans.domain(spec).surface_levels[0]


def test_the_uuv_alone_is_the_station_s_uuv_without_the_submarine(tmp_path):
    """The free stream of a two-body station: the same UUV, water, speed and heading, no submarine;
    a quarter domain at zero heading; one case per speed, heading and hull the stations need."""
    row = rans_campaign.TWO_BODY_STATIONS[0].row
    pair, alone = rans.two_body_case(row), rans.uuv_alone_case(row)
    (uuv,) = alone.bodies
    assert alone.kind == "uuv-alone" and uuv.x == uuv.y == 0.0
    assert (uuv.length, uuv.diameter, uuv.psi) == (pair.body.length, pair.body.diameter, pair.body.psi)
    assert (alone.speed, alone.rho, alone.nu, alone.level) == (pair.speed, pair.rho, pair.nu, pair.level)
    assert alone.quarter and not rans.uuv_alone_case((0, 0, 3.4, 5.0, 19.55, 10)).quarter
    assert alone.start_iterations == pair.start_iterations
    assert rans_campaign.free_stream_key(alone.inputs) == rans_campaign.free_stream_key(row)
    folder = rans.write_case(alone, tmp_path / "alone")
    assert "forces_submarine" not in _foam(folder / "system/controlDict")["functions"]
    needed = {rans_campaign.free_stream_key(s.row) for s in rans_campaign.TWO_BODY_STATIONS}
    suite = rans_campaign.suite("uuv-alone")
    assert {rans_campaign.free_stream_key(s.inputs) for s in suite} == needed and len(suite) == len(needed)
    assert [s.quarter for s in suite] == sorted((s.quarter for s in suite), reverse=True)  # cheap ones first
    # A suite takes --turbulence (its own case ids), or refuses it where its cases name their model.
    komega = rans_campaign.suite("uuv-alone", "komega")
    assert [s.case_id for s in komega] == [s.case_id + "-komega" for s in suite]
    assert {s.turbulence for s in komega} == {"komega"}
    with pytest.raises(rans.CaseError, match="--turbulence komega: the smoke suite"):
        rans_campaign.suite("smoke", "komega")


# --- forces, nondimensionalisation, verdict ------------------------------------------------------


def test_force_parsing_of_a_recorded_history(tmp_path):
    shutil.copytree(DATA / "forces_suboff", tmp_path / "postProcessing" / "forces_suboff")
    iterations, force, moment = rans.force_history(tmp_path, "suboff")
    assert len(iterations) == 40 and iterations[0] == 1 and iterations[-1] == 40
    assert force[-1] == pytest.approx([-2.00272276e01, 2.53772751e02, 2.53754807e02])
    assert moment[0] == pytest.approx([5.48606343e-03, 4.43211327e02, -4.27766784e02])


def test_half_and_quarter_domains_scale_the_forces():
    half = rans.suboff_case(4.07)
    force = np.array([[-40.0, 3.0, 7.0]])
    moment = np.array([[1.0, 2.0, 5.0]])
    psi = math.radians(4.07)
    xyz = rans.body_axes_history(half, half.body, force, moment)[0]
    assert xyz[0] == pytest.approx(2 * (-40 * math.cos(psi) + 3 * math.sin(psi)))
    assert xyz[1] == pytest.approx(2 * (40 * math.sin(psi) + 3 * math.cos(psi)))
    assert xyz[2] == pytest.approx(10.0)
    quarter = rans.suboff_case(0.0)
    assert rans.body_axes_history(quarter, quarter.body, force, moment)[0] == pytest.approx([-160.0, 0.0, 0.0])


def test_nondimensionalisation_reproduces_table_3_1():
    spec = rans.suboff_case(0.0)
    x_prime = rans.TABLE_3_1_EFD_X / rans.coefficient_scale(spec, spec.body)[0]
    assert x_prime == pytest.approx(rans.TABLE_3_1_EFD_XPRIME, rel=5e-3)  # -87.4 N <-> -9.95e-4


def _history(n=300, final=(-1e-3, 4e-4, 9e-4), wobble=0.0):
    t = np.arange(n)[:, None]
    return np.array(final) * (1 - np.exp(-t / 30.0)) + wobble * np.sin(t / 3.0)


def test_verdict_converged_not_converged_diverged():
    ok, mean = rans.verdict(_history(), {"p": 1e-5})
    assert ok.status == "converged" and ok.usable and mean == pytest.approx([-1e-3, 4e-4, 9e-4], rel=1e-3)
    wobbly, _ = rans.verdict(_history(wobble=2e-5), {})
    assert wobbly.status == "not converged" and not wobbly.usable and "X'" in wobbly.reason
    crashed, _ = rans.verdict(_history(), {}, failure="simpleFoam failed (exit 1): Maximum number of iterations")
    assert crashed.status == "diverged" and "simpleFoam" in crashed.reason
    history = _history()
    history[-1, 1] = np.nan
    assert rans.verdict(history, {})[0].status == "diverged"
    history[-1, 1] = 3.0
    assert rans.verdict(history, {})[0].status == "diverged"
    assert rans.verdict(np.zeros((0, 3)), {})[0].status == "diverged"


def test_grid_convergence_index_of_a_second_order_sequence():
    r, exact = math.sqrt(2), -1.0e-3
    f = [exact + 4e-5 * h**2 for h in (1.0, r, 2.0)]  # fine, medium, coarse
    g = rans_campaign.grid_convergence(*f, ratio=r)
    assert g["p"] == pytest.approx(2.0) and g["extrapolated"] == pytest.approx(exact)
    assert g["gci_fine"] == pytest.approx(1.25 * abs((f[1] - f[0]) / f[0]) / (r**2 - 1))
    oscillating = rans_campaign.grid_convergence(1.0, 2.0, 1.5, r)
    assert math.isnan(oscillating["p"]) and oscillating["oscillation_fine"] == pytest.approx(0.5)  # (2 - 1) / 2 / 1
    assert math.isnan(g["oscillation_fine"])
    growing = rans_campaign.grid_convergence(1.0, 1.5, 1.8, r)  # fine change 0.5 > coarse change 0.3
    assert math.isnan(growing["gci_fine"]) and growing["ratio"] == pytest.approx(0.5 / 0.3)
    # Medium and fine agreeing by chance give an observed order of 6: the GCI credits only 2.
    f = [exact + 4e-5 * h**6 for h in (1.0, r, 2.0)]
    g = rans_campaign.grid_convergence(*f, ratio=r)
    assert g["p"] == pytest.approx(6.0)
    assert g["gci_fine"] == pytest.approx(1.25 * abs((f[1] - f[0]) / f[0]) / (r**2 - 1))


# --- bad input -----------------------------------------------------------------------------------


def test_bad_configurations_are_refused():
    with pytest.raises(rans.CaseError, match="clearance"):
        rans.two_body_case([0.0, 0.05, 3.5, 0.0, 20.0, 8.0])  # inside the submarine
    with pytest.raises(rans.CaseError, match="--level"):
        rans.suboff_case(0.0, "huge")
    with pytest.raises(rans.CaseError, match="u_kn"):
        rans.two_body_case([0.0, 0.08, 0.0, 0.0, 20.0, 8.0])
    with pytest.raises(rans.CaseError, match="--suite"):
        rans_campaign.suite("everything")


def test_cli_bad_input_is_one_line_exit_2(tmp_path):
    touching = nearsub("cfd", "case", "--config", "0", "0.05", "3.5", "0", "20", "8", "-o", str(tmp_path / "x"))
    assert touching.returncode == 2 and "clearance" in touching.stderr and "Traceback" not in touching.stderr
    assert len(touching.stderr.strip().splitlines()) == 1
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "keep").write_text("mine")
    busy = nearsub("cfd", "case", "-o", str(tmp_path / "full"))
    assert busy.returncode == 2 and "not empty" in busy.stderr and (tmp_path / "full" / "keep").read_text() == "mine"
    commit = nearsub("cfd", "run", "--commit", "--work-dir", str(tmp_path / "w"))
    assert commit.returncode == 2 and "--export" in commit.stderr


def test_missing_openfoam_is_one_line(monkeypatch):
    monkeypatch.setenv("PATH", "/nonexistent")
    assert "apt-get install openfoam" in rans.openfoam_missing()


# --- end to end ----------------------------------------------------------------------------------


def _need_openfoam():
    missing = rans.openfoam_missing()
    if missing and shutil.which("apt-get") is None:
        pytest.skip(f"{missing}, and apt-get is not available to install it")
    assert missing is None, f"{missing} (tools/test.sh installs it)"


@pytest.mark.timeout(420)  # 40-100 s measured on the shared 2-core machine (load average 5-12)
def test_smoke_case(tmp_path):
    """Mesh, solve and read a coarse SUBOFF on 2 cores, on a Dask worker: the resistance has the sign and order of
    thesis table 3.1's EFD (X' = -9.95e-4), the case converges, and the artefacts are small. A first run is
    killed after its first write, as an ended session kills a runner: the Dask run goes on from that write on
    the same mesh, and the force history holds every iteration once."""
    _need_openfoam()
    from distributed import LocalCluster

    spec = rans_campaign.suite("smoke")[0]
    folder = tmp_path / "work" / spec.case_id
    code = "from nearsub.common.hydro import rans, rans_campaign as c; "
    code += f"rans.run_case(c.suite('smoke')[0], {str(folder)!r}, 2)"
    first = subprocess.Popen([sys.executable, "-c", code], start_new_session=True)
    try:
        deadline = time.monotonic() + 240
        while rans._latest_time(folder) == 0 and first.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.wait()
    written = rans._latest_time(folder)
    assert 0 < written < spec.end_iteration and not (folder / "result.json").exists()
    meshed_at = (folder / "log.snappyHexMesh").stat().st_mtime
    # As `cfd run --scheduler` runs it: one Dask task on a worker process.
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        outcomes = rans_campaign.run_cases(
            [spec], tmp_path / "work", cores=2, scheduler=cluster.scheduler_address, export_dir=tmp_path / "kept"
        )
    assert "error" not in outcomes[0], outcomes[0]
    result = rans.Result.from_json(outcomes[0])
    assert result.convergence.status == "converged", result.convergence.reason
    assert 5_000 < result.cells < 200_000
    assert -2e-3 < result.coefficients["X"] < -5e-4  # EFD -9.95e-4 (thesis table 3.1)
    assert result.forces["suboff"]["X"] == pytest.approx(result.coefficients["X"] * 0.5 * 997 * 3.05**2 * 4.3561**2)
    assert result.convergence.residuals["p"] < 1e-2 and result.y_plus["suboff"]["mean"] > 0
    assert (folder / "log.snappyHexMesh").stat().st_mtime == meshed_at  # the mesh was kept
    assert (folder / f"log.simpleFoam.{written:g}").is_file()  # the interrupted run's log
    iterations = rans.force_history(folder, "suboff")[0]
    np.testing.assert_array_equal(iterations, np.arange(1, len(iterations) + 1))
    assert iterations[-1] > written
    kept = tmp_path / "kept" / spec.case_id
    assert (kept / "postProcessing/forces_suboff/0/force.dat").is_file() and (kept / "system/controlDict").is_file()
    assert not list(kept.rglob("polyMesh")) and not list(kept.rglob("*.stl"))
    assert sum(f.stat().st_size for f in kept.rglob("*") if f.is_file()) < 2_000_000
    # Finished: a second run skips it.
    assert rans_campaign.run_cases([spec], tmp_path / "work", cores=2, export_dir=tmp_path / "kept") == []
    report = nearsub("cfd", "report", "--from", str(tmp_path / "kept"), "--json")
    assert json.loads(report.stdout)[0]["case_id"] == spec.case_id


@pytest.mark.cfd
def test_suboff_validation():
    """The SUBOFF validation (hours on 2 cores): resistance within 2 % of thesis table 3.1's EFD
    on the medium mesh, X' and N' within 10 % of table 3.2's EFD at 2.08, 4.07 and 6.03 deg, Y'
    at 4.07 and 6.03. Reuses finished cases in NEARSUB_CFD_WORK_DIR (default ./cfd-runs)."""
    _need_openfoam()
    work = Path(os.environ.get("NEARSUB_CFD_WORK_DIR", "cfd-runs"))
    rans_campaign.run_cases(rans_campaign.suite("suboff-validation"), work, cores=2)
    table = rans_campaign.validation_rows(rans_campaign.results([work]))
    medium = next(r for r in table["resistance"] if r["case"] == "suboff-psi0.00-medium")
    assert medium["meets"], f"resistance {medium['X_N']:.1f} N, {medium['error']:+.1%} against EFD"
    for row in table["drift"]:
        if row["psi"] in rans_campaign.DRIFT_ANGLES:
            assert row["meets"], f"drift {row['psi']}: errors {row['error']}"


def test_commit_artefacts_commits_only_its_folder(tmp_path, monkeypatch):
    """The runner commits a finished case's folder alone: work staged by someone else stays staged."""
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q", str(tmp_path)], check=True)
    subprocess.run([*git, "commit", "-q", "--allow-empty", "-m", "start"], cwd=tmp_path, check=True)
    (tmp_path / "other.txt").write_text("staged by someone else")
    subprocess.run([*git, "add", "other.txt"], cwd=tmp_path, check=True)
    case = tmp_path / "cases" / "suboff-psi0.00-medium"
    case.mkdir(parents=True)
    (case / "result.json").write_text("{}")
    for who in ("AUTHOR", "COMMITTER"):
        monkeypatch.setenv(f"GIT_{who}_NAME", "t")
        monkeypatch.setenv(f"GIT_{who}_EMAIL", "t@t")
    assert rans_campaign.commit_artefacts(case, "rans: a case")

    def names(*args):
        return subprocess.run(["git", *args], cwd=tmp_path, capture_output=True, text=True).stdout.split()

    assert names("show", "--name-only", "--format=") == ["cases/suboff-psi0.00-medium/result.json"]
    assert names("diff", "--cached", "--name-only") == ["other.txt"]


def test_a_rank_killed_by_a_floating_point_exception_is_named(tmp_path):
    log = tmp_path / "log.simpleFoam"
    log.write_text(
        "Time = 12\n[vm:1] Signal: Floating point exception (8)\n"
        "--------------------------------------------------------------------------\n"
        "mpiexec noticed that process rank 1 with PID 0 on node vm exited on signal 8 (Floating point exception).\n"
        "--------------------------------------------------------------------------\n"
    )
    assert rans._fatal_line(log) == "exited on signal 8 (Floating point exception)."


def test_a_case_without_its_boundary_layers_is_refused(tmp_path):
    """snappyHexMesh's last layer summary decides: under half of the layers is a bad mesh."""
    summary = "patch faces layers overall thickness\n-----\n{} 5553 {} 7.6e-06 0.246\n"
    (tmp_path / "log.snappyHexMesh").write_text(summary.format("suboff", "7.8") + summary.format("suboff", "0.00972"))
    assert rans.layers_added(tmp_path / "log.snappyHexMesh", "suboff") == pytest.approx(0.00972)
    shutil.copytree(DATA / "forces_suboff", tmp_path / "postProcessing" / "forces_suboff")
    spec = rans.suboff_case(0.0, "smoke")
    result = rans.read_result(spec, tmp_path, cells=1, cores=1, mesh_seconds=0.0, solve_seconds=0.0)
    assert result.convergence.status == "bad mesh" and not result.convergence.usable
    assert "0.0097 of 8 boundary layers" in result.convergence.reason
    # A sublayer-resolving case is judged against its own layer count.
    resolved = rans.suboff_case(0.0, "medium", "spalding", 1.0)
    wanted = rans.boundary_layers(resolved)[0]
    verdicts = {}
    for added in (0.4 * wanted, 0.9 * wanted):
        (tmp_path / "log.snappyHexMesh").write_text(summary.format("suboff", f"{added:.1f}"))
        result = rans.read_result(resolved, tmp_path, cells=1, cores=1, mesh_seconds=0.0, solve_seconds=0.0)
        verdicts[added] = result.convergence
    low, high = verdicts.values()
    assert low.status == "bad mesh" and f"of {wanted} boundary layers" in low.reason
    assert high.status != "bad mesh"


# --- two-body suite and the side-by-side comparison ------------------------------------------------


def test_two_body_suite_has_24_buildable_stations_8_held_out():
    from nearsub.common.hydro.low_fidelity import input_columns
    from nearsub.common.physics.proximity import closest_distance

    stations = rans_campaign.TWO_BODY_STATIONS
    specs = rans_campaign.suite("two-body")  # two_body_case refuses what the mesher cannot build
    assert len(specs) == len(stations) >= 24 and len({s.case_id for s in specs}) == len(specs)
    assert sum(s.held_out for s in stations) >= 8 and all(s.level == "medium" for s in specs)
    rows = np.array([s.row for s in stations])
    x, y, _, psi, diameter, length = input_columns(rows)
    gaps = closest_distance(x, y, psi, length[0], diameter[0])  # every SDV row shares its size
    sdv = (rows[:, 4] == rans_campaign.SDV_RATIOS[0]) & (rows[:, 5] == rans_campaign.SDV_RATIOS[1])
    stern = [i for i, s in enumerate(stations) if s.name.startswith("stern -0.") and "gap" in s.name]
    assert len(stern) == 9 and all(sdv[stern])
    expected = np.tile(rans_campaign.STERN_GAPS_M, 3)
    assert np.allclose(np.asarray(gaps)[stern], expected, atol=0.01)  # the overtake's 0.15-1.3 m
    assert np.any(np.abs(rows[:, 3]) == 5.0)  # one beyond table 4.2's heading
    from nearsub.common.surrogate.domain import constraint_values

    assert np.any(constraint_values(rows)[:, 1] < 0)  # stations beyond (4.5)
    grid = rans_campaign.suite("two-body-grid")
    assert [s.level for s in grid] == ["coarse", "medium", "fine"] and grid[1] in specs
    assert rans_campaign.station_of(stations[4].row) == stations[4] and rans_campaign.station_of(None) is None


def test_two_body_cases_start_first_order_and_suboff_does_not():
    assert rans.two_body_case(rans_campaign.TWO_BODY_STATIONS[0].row, "medium").start_iterations == 50
    assert rans.suboff_case(2.08).start_iterations == 0
    assert rans.two_body_case(rans_campaign.TWO_BODY_STATIONS[0].row, "medium", iterations=40).start_iterations == 10
    # A SUBOFF case resolving its sublayer starts first order, for longer than the two-body cases.
    resolved = rans.suboff_case(0.0, "medium", "spalding", 1.0)
    assert resolved.start_iterations == rans.RESOLVED_FIRST_ORDER_START > rans.FIRST_ORDER_START
    assert rans.suboff_case(0.0, "medium", "spalding", 30.0).start_iterations == 0


def test_force_history_joins_the_stages_of_a_case(tmp_path):
    """A first-order start writes forces into postProcessing/forces_*/0 and /<start>: one history."""
    recorded = DATA / "forces_suboff" / "0"
    for start, rows in (("0", slice(0, 15)), ("15", slice(15, None))):
        folder = tmp_path / "postProcessing" / "forces_suboff" / start
        folder.mkdir(parents=True)
        for name in ("force.dat", "moment.dat"):
            lines = (recorded / name).read_text().splitlines()
            header = [ln for ln in lines if ln.startswith("#")]
            body = [ln for ln in lines if ln.strip() and not ln.startswith("#")]
            (folder / name).write_text("\n".join(header + body[rows]) + "\n")
    iterations, force, _ = rans.force_history(tmp_path, "suboff")
    assert len(iterations) == 40 and list(iterations) == list(range(1, 41))
    assert force[-1] == pytest.approx([-2.00272276e01, 2.53772751e02, 2.53754807e02])


def _result(inputs, coefficients, status="converged"):
    return rans.Result(
        case_id="tb-" + "_".join(f"{v:g}" for v in inputs) + "-medium",
        kind="two-body",
        level="medium",
        wall_function="nutk",
        y_plus_target=50.0,
        cells=400_000,
        cores=2,
        mesh_seconds=300.0,
        solve_seconds=900.0,
        coefficients=dict(zip("XYN", coefficients, strict=True)),
        forces={},
        convergence=rans.Convergence(status, "", 800, 160, {}, {}),
        inputs=tuple(inputs),
    )


def test_comparison_table_arithmetic():
    stations = rans_campaign.TWO_BODY_STATIONS
    held = next(s for s in stations if s.held_out)
    kept = next(s for s in stations if not s.held_out)
    results = rans_comparison.two_body_converged(
        [
            _result(held.row, (-1.0e-3, -4.0e-4, 2.0e-4)),
            _result(kept.row, (-2.0e-3, 1.0e-4, -1.0e-4)),
            _result(kept.row[:1] + (0.099,) + kept.row[2:], (9.0, 9.0, 9.0), status="not converged"),
        ]
    )
    assert len(results) == 2 and results[0].inputs[0] <= results[1].inputs[0]
    order = [1 if r.inputs == held.row else 0 for r in results]
    hf = np.array([[-1.5e-3, 2.0e-4, -1.0e-4], [-1.2e-3, -2.0e-4, 3.0e-4]])
    rows = rans_comparison.comparison_rows(results, {"panel HF": hf})
    by_held = {r["held_out"]: r for r in rows}
    assert by_held[True]["station"] == held.name and by_held[False]["station"] == kept.name
    i_held = order.index(1)
    assert by_held[True]["panel HF - RANS"] == pytest.approx((hf[i_held] - [-1.0e-3, -4.0e-4, 2.0e-4]).tolist())
    assert by_held[True]["panel HF rel"][1] == pytest.approx((hf[i_held][1] + 4.0e-4) / 4.0e-4)
    summary = rans_comparison.comparison_summary(rows, ["panel HF"])["panel HF"]
    diffs = np.abs(np.array([r["panel HF - RANS"] for r in rows]))
    assert summary["mae"] == pytest.approx(diffs.mean(axis=0).tolist())
    assert summary["mae_held_out"] == pytest.approx(np.abs(by_held[True]["panel HF - RANS"]).tolist())
    signs = np.mean(np.sign(np.array([r["panel HF"] for r in rows])) == np.sign(np.array([r["RANS"] for r in rows])), 0)
    assert summary["sign_agrees"] == pytest.approx(signs.tolist())


def test_compare_without_a_converged_two_body_case_is_one_line(tmp_path):
    (tmp_path / "cases").mkdir()
    out = nearsub("cfd", "compare", "--from", str(tmp_path / "cases"), "-o", str(tmp_path / "out"))
    assert out.returncode == 2 and "no converged two-body case" in out.stderr and "Traceback" not in out.stderr
    assert not (tmp_path / "out").exists()


def test_sustained_inflow_turbulence_is_its_own_case(tmp_path):
    spec = rans.suboff_case(0.0, "medium", sustain_inflow=True)
    assert spec.case_id == "suboff-psi0.00-medium-sust" and rans.suboff_case(0.0).case_id == "suboff-psi0.00-medium"
    folder = rans.write_case(spec, tmp_path / "s")
    coeffs = _foam(folder / "constant/turbulenceProperties")["RAS"]["kOmegaSSTCoeffs"]
    k, omega = rans.inflow_turbulence(spec)
    assert (
        coeffs["decayControl"] is True
        and coeffs["kInf"] == pytest.approx(k)
        and coeffs["omegaInf"] == pytest.approx(omega)
    )
    assert rans.load_spec(folder) == spec
    refused = nearsub(
        "cfd", "case", "--config", "0", "0.08", "3.5", "0", "20", "8", "--sustain-inflow", "-o", str(tmp_path / "x")
    )
    assert refused.returncode == 2 and "--sustain-inflow" in refused.stderr


def test_wilcox_k_omega_is_its_own_case(tmp_path):
    spec = rans.suboff_case(0.0, "medium", "spalding", 1.0, turbulence="komega")
    assert spec.case_id == "suboff-psi0.00-medium-spalding-yp1-komega"
    folder = rans.write_case(spec, tmp_path / "w")
    assert _foam(folder / "constant/turbulenceProperties")["RAS"]["RASModel"] == "kOmega"
    assert rans.load_spec(folder) == spec
    default = rans.write_case(rans.suboff_case(0.0, "medium", "spalding", 1.0), tmp_path / "d")
    assert _foam(default / "constant/turbulenceProperties")["RAS"]["RASModel"] == "kOmegaSST"
    for bad in ({"turbulence": "kEpsilon"}, {"turbulence": "komega", "sustain_inflow": True}):
        with pytest.raises(rans.CaseError, match="--turbulence|--sustain-inflow"):
            rans.suboff_case(0.0, **bad)
    two_body = rans.two_body_case([0, 0.08, 3.5, 0, 20, 8], "medium", turbulence="komega")
    assert two_body.case_id == "tb-0_0.08_3.5_0_20_8-medium-komega"
    assert two_body.case_id != rans.two_body_case([0, 0.08, 3.5, 0, 20, 8]).case_id  # never compared as the SST station
    built = rans.write_case(two_body, tmp_path / "t")
    assert _foam(built / "constant/turbulenceProperties")["RAS"]["RASModel"] == "kOmega"
    refused = nearsub("cfd", "case", "--config", "0", "0.08", "3.5", "0", "20", "8", "--sustain-inflow")
    assert refused.returncode == 2 and "--sustain-inflow" in refused.stderr and "Traceback" not in refused.stderr
    unknown = nearsub("cfd", "case", "--turbulence", "kEpsilon", "-o", str(tmp_path / "x"))
    assert unknown.returncode == 2 and "--turbulence 'kEpsilon'" in unknown.stderr and not (tmp_path / "x").exists()


def test_the_inflow_turbulence_is_a_case_option(tmp_path):
    spec = rans.with_inflow(rans.suboff_case(0.0, "medium", "spalding", 1.0, turbulence="komega"), 0.001, 1.0)
    assert spec.case_id == "suboff-psi0.00-medium-spalding-yp1-komega-tu0.1-vr1"
    folder = rans.write_case(spec, tmp_path / "i")
    k, omega = 1.5 * (0.001 * spec.speed) ** 2, 1.5 * (0.001 * spec.speed) ** 2 / (1.0 * spec.nu)
    assert rans.inflow_turbulence(spec) == pytest.approx((k, omega), rel=1e-12)
    assert _foam(folder / "0.orig/k")["internalField"] == pytest.approx(k)
    assert _foam(folder / "0.orig/omega")["boundaryField"]["inlet"]["value"] == pytest.approx(omega)
    assert rans.load_spec(folder) == spec
    default = rans.suboff_case(0.0)
    assert rans.with_inflow(default, rans.INFLOW_INTENSITY, rans.INFLOW_VISCOSITY_RATIO) is default
    for intensity, ratio, field in ((0.5, 10.0, "--inflow-intensity"), (0.01, 0.0, "--inflow-viscosity-ratio")):
        with pytest.raises(rans.CaseError, match=field):
            rans.with_inflow(default, intensity, ratio)
    made = nearsub(
        "cfd", "case", "--inflow-intensity", "0.1", "--inflow-viscosity-ratio", "1", "-o", str(tmp_path / "c")
    )
    assert made.returncode == 0, made.stderr
    assert json.loads((tmp_path / "c" / "case.json").read_text())["inflow_intensity"] == pytest.approx(0.001)
    refused = nearsub("cfd", "case", "--inflow-intensity", "50", "-o", str(tmp_path / "x"))
    assert refused.returncode == 2 and "--inflow-intensity 50" in refused.stderr and "Traceback" not in refused.stderr
    assert not (tmp_path / "x").exists()


def test_a_result_without_its_model_and_inflow_takes_them_from_its_case(tmp_path):
    """Results written before the turbulence model and the inflow were recorded in result.json
    show them all the same in the tables: `results` reads them from the case's case.json."""
    spec = rans.with_inflow(rans.suboff_case(0.0, "medium", "spalding", 1.0, turbulence="komega"), 0.01, 100.0)
    _saved(tmp_path / spec.case_id, spec, "converged", 300)
    saved = json.loads((tmp_path / spec.case_id / "result.json").read_text())
    for key in ("turbulence", "inflow_intensity", "inflow_viscosity_ratio"):
        del saved[key]
    saved["forces"] = {"suboff": {"X": -88.0, "Y": 0.0, "N": 0.0}}
    (tmp_path / spec.case_id / "result.json").write_text(json.dumps(saved))
    (tmp_path / spec.case_id / "case.json").write_text(json.dumps(spec.describe()))
    [found] = rans_campaign.results([tmp_path])
    assert (found.turbulence, found.inflow_intensity, found.inflow_viscosity_ratio) == ("komega", 0.01, 100.0)
    [row] = rans_campaign.validation_rows([found])["resistance"]
    assert row["turbulence"] == "komega" and row["inflow"] == (0.01, 100.0)


def test_the_finer_meshes_smooth_the_shrinking_for_their_layer_stack():
    """The wall-function stack keeps its thickness while the cells shrink: past two surface cells
    (the fine and xfine two-body meshes) snappyHexMesh smooths the displacement that makes room for
    it; the coarse and medium meshes, and the sublayer recipe, are made as before."""
    row = [-0.39, 0.0671, 3.4, 0, 19.55, 10]
    smoothing = {}
    for level in ("coarse", "medium", "fine", "xfine"):
        spec = rans.two_body_case(row, level)
        dom = rans.domain(spec)
        stack = rans.first_layer_thickness(spec) * (1.25**8 - 1.0) / 0.25
        assert rans.layer_stack_cells(spec, dom) == pytest.approx(stack * 2 ** dom.surface_levels[0] / dom.background)
        smoothing[level] = rans._snappy(spec, dom)["addLayersControls"].get("nSmoothDisplacement")
    assert smoothing == {"coarse": None, "medium": None, "fine": 90, "xfine": 90}
    resolved = rans.suboff_case(0.0, "fine", "spalding", 1.0)
    controls = rans._snappy(resolved, rans.domain(resolved))["addLayersControls"]
    assert "nSmoothDisplacement" not in controls and controls["nRelaxedIter"] == 0


def test_a_diverged_case_shows_no_resistance(tmp_path):
    """The last numbers of a case that blew up (1e30 N) are no answer: the table leaves them blank."""
    spec = rans.suboff_case(0.0, "medium", "spalding", 1.0)
    _saved(tmp_path / spec.case_id, spec, "diverged", 96)
    saved = json.loads((tmp_path / spec.case_id / "result.json").read_text())
    saved["forces"] = {"suboff": {"X": 5.9e33, "Y": 0.0, "N": 0.0}}
    saved["coefficients"]["X"] = 6.7e28
    (tmp_path / spec.case_id / "result.json").write_text(json.dumps(saved))
    out = nearsub("cfd", "validate", "--from", str(tmp_path))
    [row] = [line for line in out.stdout.splitlines() if line.startswith(f"| {spec.case_id} |")]
    assert row.endswith("|  |  |  | diverged |") and "e+" not in row and "5900" not in row


def _saved(folder: Path, spec: rans.CaseSpec, status: str, iterations: int) -> None:
    convergence = rans.Convergence(status, "", iterations, iterations // 5, {"X": 0.0, "Y": 0.0, "N": 0.0}, {})
    result = rans.Result(spec.case_id, spec.kind, spec.level, spec.wall_function, spec.y_plus, 1, 2, 1.0, 1.0,
                         {"X": 0.0, "Y": 0.0, "N": 0.0}, {}, convergence)  # fmt: skip
    folder.mkdir(parents=True)
    (folder / "result.json").write_text(json.dumps(result.to_json()))


def test_a_case_residual_control_stopped_before_its_forces_settled_is_continued(tmp_path):
    """Residual control (p at 1e-4) stopped the two-body stations after 150-230 of their 800
    iterations, some with their forces still moving: such a case is run again from its work
    folder, without residual control, while one with only its artefacts left stays as it is."""
    specs = [rans.two_body_case((-0.45, 0.0391 + 0.001 * i, 3.4, 0.0, 19.55, 10.0)) for i in range(4)]
    work, kept = tmp_path / "work", tmp_path / "kept"
    _saved(work / specs[0].case_id, specs[0], "not converged", 169)  # stopped early: continue
    _saved(work / specs[1].case_id, specs[1], "not converged", specs[1].end_iteration)  # ran to its end
    _saved(work / specs[2].case_id, specs[2], "converged", 172)
    _saved(kept / specs[3].case_id, specs[3], "not converged", 169)  # no work folder to continue from
    assert rans_campaign.unfinished(specs, work, kept) == [specs[0]]
    assert "residualControl" in rans.FV_SOLUTION["SIMPLE"]
    assert "residualControl" not in rans.FV_SOLUTION_TO_END["SIMPLE"]


def test_the_fitted_scale_uses_the_training_stations_of_the_medium_mesh_only():
    def row(hf, truth, held_out=False, level="medium"):
        return {"panel HF": hf, "RANS": truth, "held_out": held_out, "level": level}

    rows = [
        row([-1.0e-3, 2.0e-4, -1.0e-4], [-0.9e-3, 1.6e-4, -0.7e-4]),
        row([-2.0e-3, -1.0e-4, 3.0e-4], [-1.8e-3, -0.8e-4, 2.1e-4]),
        row([-1.0e-3, 1.0e-4, 1.0e-4], [5.0, 5.0, 5.0], held_out=True),  # never fitted to
        row([-1.0e-3, 1.0e-4, 1.0e-4], [5.0, 5.0, 5.0], level="fine"),  # the grid study's other meshes
    ]
    assert rans_comparison.fitted_scale(rows) == pytest.approx([0.9, 0.8, 0.7])
    assert np.isnan(rans_comparison.fitted_scale(rows[2:])).all()


def test_the_two_body_gci_needs_all_three_meshes_converged_and_judges_each_output():
    from types import SimpleNamespace

    def result(level, x, y, n, usable=True):
        case = rans.two_body_case(rans_campaign.GRID_STATION.row, level).case_id
        return case, SimpleNamespace(coefficients={"X": x, "Y": y, "N": n}, convergence=SimpleNamespace(usable=usable))

    # X' converges monotonically (GCI small), Y' barely (GCI large), N' oscillates (undefined)
    found = dict(
        [
            result("coarse", -1.00, -0.100, 0.030),
            result("medium", -0.96, -0.070, 0.036),
            result("fine", -0.95, -0.050, 0.033),
        ]
    )
    gci = rans_campaign.two_body_gci(found)
    assert gci["X"]["meets"] and not gci["Y"]["meets"] and not gci["N"]["meets"]
    assert np.isnan(gci["N"]["gci_fine"])
    assert rans_campaign.two_body_gci(dict([*list(found.items())[:2], result("fine", 0, 0, 0, usable=False)])) is None
    # A fourth, finer mesh: the three finest make a second triplet, judged on the xfine mesh.
    finer = rans_campaign.GRID_TRIPLETS[1]
    assert rans_campaign.two_body_gci(found, triplet=finer) is None
    found.update([result("xfine", -0.945, -0.040, 0.032)])
    gci = rans_campaign.two_body_gci(found, triplet=finer)
    assert gci["X"]["ratio"] == pytest.approx(0.5) and gci["X"]["meets"]
    assert gci["Y"]["ratio"] == pytest.approx(0.5) and not gci["Y"]["meets"]  # 20 % of Y' on the finest mesh
    # N': order 3.2, credited 2: GCI 1.25 x 0.001 / 0.032 / (2 - 1)
    assert gci["N"]["ratio"] == pytest.approx(1 / 3) and gci["N"]["gci_fine"] == pytest.approx(0.0391, abs=1e-4)


def test_the_held_out_summary_counts_each_held_out_station_once_on_its_medium_mesh():
    def row(diff, held_out, level="medium"):
        return {"RANS": [1.0, 1.0, 1.0], "held_out": held_out, "level": level,
                "panel HF": [1.0 + diff] * 3, "panel HF - RANS": [diff] * 3}  # fmt: skip

    rows = [row(0.1, True), row(0.3, True), row(5.0, True, level="coarse"), row(1.0, False)]
    summary = rans_comparison.comparison_summary(rows, ["panel HF"])["panel HF"]
    assert summary["mae_held_out"] == pytest.approx([0.2] * 3)  # the coarse mesh of a station is left out
    assert summary["mae"] == pytest.approx([1.6] * 3)  # every row


def test_a_studys_variant_never_stands_in_for_a_station_or_its_uuv_alone(tmp_path):
    """The k-omega and inflow variants share their station's inputs: the comparison, the
    interaction alone and the viscous correction take only the suites' setup (SST, the default
    inflow), whatever order the folders are read in."""
    from nearsub.common.analysis import rans_comparison

    row = [-0.39, 0.0671, 3.4, 0, 19.55, 10]
    specs = {
        "station": rans.two_body_case(row),
        "station-komega": rans.two_body_case(row, turbulence="komega"),
        "station-inflow": rans.with_inflow(rans.two_body_case(row), 0.01, 100.0),
        "alone": rans.uuv_alone_case(row),
        "alone-komega": rans.uuv_alone_case(row, turbulence="komega"),
        "alone-inflow": rans.with_inflow(rans.uuv_alone_case(row), 0.001, 10.0),
    }
    for name, spec in specs.items():
        _saved(tmp_path / name, spec, "converged", 300)
        saved = json.loads((tmp_path / name / "result.json").read_text())
        saved |= {
            "inputs": list(spec.inputs),
            "turbulence": spec.turbulence,
            "inflow_intensity": spec.inflow_intensity,
            "inflow_viscosity_ratio": spec.inflow_viscosity_ratio,
        }
        (tmp_path / name / "result.json").write_text(json.dumps(saved))
    found = rans_campaign.results([tmp_path])
    assert [r.case_id for r in rans_comparison.two_body_converged(found)] == [specs["station"].case_id]
    assert [r.case_id for r in rans_comparison.uuv_alone(found).values()] == [specs["alone"].case_id]
