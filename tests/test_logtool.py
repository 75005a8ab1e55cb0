"""`nearsub log info` and `export` on a log written the way the logger writes it."""

import csv
import io
import json

import pytest
from logsample import write_sample_log

from conftest import nearsub


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("log") / "alpha.mcap"
    return path, write_sample_log(path)


def test_info_counts_topics_and_rates(log):
    path, result = log
    out = nearsub("log", "info", str(path), "--json")
    assert out.returncode == 0, out.stderr
    info = json.loads(out.stdout)
    assert info["topics"]["nearsub/alpha/remus100/state"]["count"] == len(result.topic("state"))
    assert info["topics"]["nearsub/alpha/remus100/state"]["hz"] == pytest.approx(20.0)
    assert info["topics"]["nearsub/alpha/remus100/desired"]["hz"] == pytest.approx(4.0)
    assert info["topics"]["nearsub/alpha/remus100/state#invalid"]["count"] == 1


def test_export_csv_of_one_topic(log):
    path, result = log
    out = nearsub("log", "export", str(path), "--format", "csv", "--topic", "nearsub/alpha/*/state")
    assert out.returncode == 0, out.stderr
    rows = list(csv.DictReader(io.StringIO(out.stdout)))
    assert len(rows) == len(result.topic("state"))
    assert float(rows[-1]["x"]) == result.topic("state")[-1].x


def test_export_json_lines(log, tmp_path):
    path, result = log
    target = tmp_path / "out.jsonl"
    out = nearsub("log", "export", str(path), "--format", "json", "--topic", "nearsub/alpha/**", "-o", str(target))
    assert out.returncode == 0, out.stderr
    lines = [json.loads(line) for line in target.read_text().splitlines()]
    inputs = [line for line in lines if line["topic"].endswith("/input")]
    assert [line["value"]["X_prop"] for line in inputs] == [m.X_prop for m in result.topic("input")]


def test_csv_of_several_topics_needs_a_folder(log, tmp_path):
    path, _ = log
    refused = nearsub("log", "export", str(path), "--format", "csv")
    assert refused.returncode == 2 and "--topic" in refused.stderr
    folder = tmp_path / "csv"
    done = nearsub("log", "export", str(path), "--format", "csv", "-o", str(folder))
    assert done.returncode == 0 and (folder / "nearsub_alpha_remus100_state.csv").exists()


def test_plot_draws_a_png(log, tmp_path):
    path, _ = log
    target = tmp_path / "plot.png"
    out = nearsub("log", "plot", str(path), "-o", str(target))
    assert out.returncode == 0, out.stderr
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and target.stat().st_size > 20000
