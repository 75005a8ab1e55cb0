"""`nearsub log info` and `export` on a log written the way the logger writes it."""

import csv
import io
import json

import pytest

from conftest import ALPHA, nearsub
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.logfile import LogWriter
from nearsub.common.runtime.messages import encode


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    mission = load_mission(ALPHA, ["time_limit=10"])
    result = run_mission(mission)
    path = tmp_path_factory.mktemp("log") / "alpha.mcap"
    writer = LogWriter(path)
    writer.metadata("mission", {"name": "alpha"})
    for role, leaf, message in result.messages:
        key = f"nearsub/alpha/events/{role}" if leaf == "events" else f"nearsub/alpha/remus100/{leaf}"
        writer.write(key, encode(message), message.t)
    writer.write("nearsub/alpha/remus100/state", b"\xc1", 10.0, valid=False)
    writer.finish()
    return path, result


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


def test_export_alog_in_moos_format(log):
    path, result = log
    out = nearsub("log", "export", str(path), "--format", "alog")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].startswith("%%")
    body = [line.split(" ", 3) for line in lines if not line.startswith("%%")]
    desired = [fields for fields in body if fields[1] == "REMUS100_DESIRED"]
    assert len(desired) == len(result.topic("desired"))
    time, variable, source, value = desired[1]
    assert float(time) == pytest.approx(0.25) and source == "helm" and "psi_d=" in value


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
