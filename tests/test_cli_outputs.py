"""Where the commands write: never over their input or the shipped docs by default, and a bad
output path or option value is one line naming it, exit code 2, before any work."""

import csv
import shutil
from pathlib import Path

import pytest
from logsample import write_sample_log

from conftest import ROOT, nearsub
from nearsub.tools import map_figures
from nearsub.tools.cli import main

SHIPPED_ENVELOPES = ROOT / "docs" / "envelopes"


def one_line(text: str) -> str:
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    return lines[0]


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("log") / "alpha.mcap"
    write_sample_log(path)
    return path


@pytest.mark.parametrize("fmt", ["json", "alog", "foxglove", "csv"])
def test_export_never_writes_over_the_log(log, tmp_path, fmt):
    own = tmp_path / log.name  # a copy each: a format that wrote over it must not hide the next
    shutil.copyfile(log, own)
    done = nearsub("log", "export", str(own), "--format", fmt, "-o", str(own))
    assert done.returncode == 2 and str(own) in one_line(done.stderr)
    assert own.read_bytes() == log.read_bytes()


@pytest.mark.parametrize("fmt", ["json", "alog", "foxglove"])
def test_export_to_a_folder_or_a_missing_folder_is_one_line(log, tmp_path, fmt):
    for target, says in ((tmp_path, "is a folder"), (tmp_path / "no" / "out.x", "no folder")):
        done = nearsub("log", "export", str(log), "--format", fmt, "-o", str(target))
        assert done.returncode == 2 and says in one_line(done.stderr)


def test_csv_export_writes_a_named_csv_file_and_refuses_a_file_as_folder(log, tmp_path):
    state = "--topic", "nearsub/alpha/remus100/state"
    target = tmp_path / "state.csv"
    done = nearsub("log", "export", str(log), "--format", "csv", *state, "-o", str(target))
    assert done.returncode == 0, done.stderr
    assert target.is_file() and "x" in next(csv.DictReader(target.open()))
    plain = tmp_path / "notes"
    plain.write_text("mine\n")
    refused = nearsub("log", "export", str(log), "--format", "csv", *state, "-o", str(plain))
    assert refused.returncode == 2 and "is a file" in one_line(refused.stderr) and plain.read_text() == "mine\n"


@pytest.mark.parametrize("fmt", ["json", "alog", "csv"])
def test_an_unmatched_topic_is_the_same_error_in_every_format(log, tmp_path, fmt):
    target = tmp_path / f"out.{fmt}"
    done = nearsub("log", "export", str(log), "--format", fmt, "--topic", "nope/x", "-o", str(target))
    assert done.returncode == 2 and "--topic nope/x: no messages match" in one_line(done.stderr)
    assert not target.exists()


def test_plot_names_the_file_it_writes_and_refuses_a_missing_folder(log, tmp_path):
    done = nearsub("log", "plot", str(log), "-o", str(tmp_path / "foo"))
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(tmp_path / "foo.png") and (tmp_path / "foo.png").exists()
    missing = nearsub("log", "plot", str(log), "-o", str(tmp_path / "no" / "x.png"))
    assert missing.returncode == 2 and "no folder" in one_line(missing.stderr)
    folder = nearsub("log", "plot", str(log), "-o", str(tmp_path))  # not <folder>.png beside it
    assert folder.returncode == 2 and "is a folder" in one_line(folder.stderr)
    assert not tmp_path.with_suffix(".png").exists()


def test_maps_draw_into_the_working_directory_by_default(tmp_path, monkeypatch, capsys):
    folders = set()
    monkeypatch.setattr(
        map_figures, "plot_figure", lambda surrogate, name, out_dir: folders.add(out_dir) or out_dir / name
    )
    monkeypatch.chdir(tmp_path)
    assert main(["maps"]) == 0
    assert folders == {Path("maps")}
    (tmp_path / "taken").write_text("")
    assert main(["maps", "--out", "taken"]) == 2
    assert "--out taken: is a file" in capsys.readouterr().err


def test_thesis_figures_default_to_the_working_directory_and_read_shipped_data(tmp_path):
    shipped = {p.name: p.stat().st_mtime_ns for p in SHIPPED_ENVELOPES.iterdir() if p.is_file()}
    done = subprocess_in(
        tmp_path, "envelope", "--thesis-figures", "--figure", "5-10", "--reuse", SHIPPED_ENVELOPES / "data"
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "thesis-envelopes" / "figure-5-10.png").exists()
    assert len(list((tmp_path / "thesis-envelopes" / "data").glob("*.json"))) == 3  # copied for the next --reuse
    assert {p.name: p.stat().st_mtime_ns for p in SHIPPED_ENVELOPES.iterdir() if p.is_file()} == shipped


def test_a_figure_run_keeps_the_other_figures_rows(tmp_path):
    for name in ("data", "fractions.csv", "fractions.md"):
        source = SHIPPED_ENVELOPES / name
        (shutil.copytree if source.is_dir() else shutil.copy)(source, tmp_path / name)
    done = nearsub("envelope", "--thesis-figures", "--figure", "5-12", "--reuse", "-o", str(tmp_path))
    assert done.returncode == 0, done.stderr
    for name in ("fractions.csv", "fractions.md"):
        assert (tmp_path / name).read_text() == (SHIPPED_ENVELOPES / name).read_text()


def subprocess_in(folder: Path, *args):
    import subprocess
    import sys

    argv = [sys.executable, "-m", "nearsub", *map(str, args)]
    return subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=folder)


@pytest.mark.parametrize(
    "option",
    [
        ("--duration", "-1"),
        ("--duration", "nan"),
        ("--dt", "0"),
        ("--sea-state", "99"),
        ("--depth", "-5"),
        ("--u-sub", "inf"),
        ("--gamma", "nan"),
        ("--d-lead", "-3"),
        ("--d-lead", "xyz"),
        ("--r-long", "nan,1"),
        ("--r-long", "0.8,-0.8"),
        ("--workers", "0"),
        ("--scheduler", "garbage"),
        ("--model", "nope.npz"),
        ("--cell-mission", "nan,0.1"),
    ],
)
def test_envelope_options_are_checked_in_one_line(tmp_path, option):
    done = subprocess_in(tmp_path, "envelope", "--grid", "2x2", "--duration", "2", *option)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert option[0] in done.stderr.splitlines()[-1] or option[1] in done.stderr.splitlines()[-1]
    assert list(tmp_path.iterdir()) == []


def test_envelope_refuses_a_file_as_its_folder(tmp_path):
    (tmp_path / "taken").write_text("")
    done = subprocess_in(tmp_path, "envelope", "--grid", "2x2", "--duration", "2", "-o", "taken")
    assert done.returncode == 2 and "-o taken: is a file" in one_line(done.stderr)


@pytest.mark.parametrize(
    "argv, says",
    [
        (("train", "--design", "sobol", "--budget", "2", "--state", "."), "--state .: is a folder"),
        (("train", "--data", "small.csv", "--out", "."), "--out .: is a folder"),
        (("train", "--budget", "2", "--scheduler", "garbage"), "--scheduler"),
        (("campaign", "next", "--state", "."), "--state .: is a folder"),
        (("campaign", "start", "--budget", "-1"), "--budget"),
        (("campaign", "start", "--budget", "5"), "--budget 5: smaller than the initial HF design"),
        (("al-bench", "park", "--repeats", "0"), "--repeats"),
        (("al-bench", "park", "--hf-samples", "3", "--repeats", "1"), "--hf-samples 3: fewer than"),
        (("al-bench", "park", "--from-files", "-o", "small.csv"), "-o small.csv: is a file"),
        (("lf-field", "-o", "no/x.npz"), "no folder"),
    ],
)
def test_training_commands_check_their_paths_and_sizes(tmp_path, argv, says):
    (tmp_path / "small.csv").write_text("R_long\n")
    done = subprocess_in(tmp_path, *argv)
    assert done.returncode == 2 and says in done.stderr.splitlines()[-1] and "Traceback" not in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.csv"]


def test_train_sobol_does_not_ask_for_seed_points():
    from nearsub.tools.commands import train

    parser = __import__("argparse").ArgumentParser()
    train.add_parser(parser.add_subparsers())
    args = parser.parse_args(["train", "--design", "sobol", "--budget", "2"])
    assert args.n_seed is None  # the adaptive designs' 20 applies to them only


@pytest.mark.parametrize(
    "point, says",
    [("R_long=nan", "R_long=nan: not a finite number"), ("R_long=inf", "R_long=inf"), ("d_ratio=0", "d_ratio=0")],
)
def test_predict_refuses_impossible_inputs(capsys, point, says):
    inputs = dict(item.split("=") for item in "R_long=0 R_lat=0.07 u_kn=3 psi_deg=0 d_ratio=10 ld_ratio=8".split())
    name, value = point.split("=")
    inputs[name] = value
    assert main(["surrogate", "predict", *(f"{k}={v}" for k, v in inputs.items())]) == 2
    out = capsys.readouterr()
    assert says in one_line(out.err) and out.out == ""


def test_surrogate_validate_and_sweep_never_write_over_what_they_read(tmp_path):
    points = tmp_path / "points.csv"
    shutil.copyfile(ROOT / "docs" / "hydro" / "validation-points.csv", points)
    before = points.read_bytes()
    done = nearsub("surrogate", "validate", "--points-file", str(points), "--out", str(points))
    assert done.returncode == 2 and "is the --points-file it reads" in one_line(done.stderr)
    table = tmp_path / "sweeps" / "sweeps.csv"
    table.parent.mkdir()
    table.write_text("anything")
    done = nearsub("surrogate", "sweep", "--hf-from", str(table), "-o", str(table.parent))
    assert done.returncode == 2 and "is the --hf-from it reads" in one_line(done.stderr)
    assert points.read_bytes() == before and table.read_text() == "anything"
    done = nearsub("surrogate", "sweep", "-o", str(points))
    assert done.returncode == 2 and "is a file, not a folder" in one_line(done.stderr)


def test_plot_of_a_log_without_states_is_bad_input(tmp_path):
    from nearsub.common.runtime.logfile import LogWriter

    path = tmp_path / "empty.mcap"
    writer = LogWriter(path)
    writer.finish()
    done = nearsub("log", "plot", str(path), "-o", str(tmp_path / "x.png"))
    assert done.returncode == 2 and one_line(done.stderr) == f"nearsub log plot: {path}: no state messages to plot"
