"""The log tools on a log of two vehicles (`logsample.write_fleet_log`): info, alog, plot."""

import json

import matplotlib
import pytest
from logsample import FLEET, write_fleet_log

from conftest import nearsub
from nearsub.common.runtime.keys import vehicle_of
from nearsub.common.runtime.logfile import read_log, vehicle_spec

matplotlib.use("Agg")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    path = tmp_path_factory.mktemp("fleet") / "alpha.mcap"
    return path, write_fleet_log(path)


def test_vehicle_of_tells_vehicle_keys_from_mission_wide_ones():
    assert vehicle_of("nearsub/alpha/bravo/state") == ("bravo", "state")
    assert vehicle_of("nearsub/alpha/events/bravo/helm-1") == ("bravo", "events")
    for key in ("nearsub/alpha/clock/end", "nearsub/alpha/events/helm", "nearsub/alpha/status/sim", "other/a/b/c"):
        assert vehicle_of(key) is None, key


def test_vehicle_spec_reads_a_fleet_entry_else_the_mission_vehicle():
    fleet = {"vehicle": "remus100", "vehicles": [{"name": "b", "type": "sdv"}]}
    assert vehicle_spec(fleet, "b") == "sdv"
    assert vehicle_spec(fleet, "a") == "remus100"
    assert vehicle_spec(None, "a") is None


def test_info_lists_each_vehicle_with_its_steps_and_time_span(fleet):
    path, result = fleet
    out = nearsub("log", "info", str(path), "--json")
    assert out.returncode == 0, out.stderr
    vehicles = json.loads(out.stdout)["vehicles"]
    assert list(vehicles) == sorted(FLEET)
    states = result.topic("state")
    assert vehicles["alfa"] == {
        "states": len(states),
        "first_step": 0,
        "last_step": states[-1].step,
        "t_start": 0.0,
        "t_end": states[-1].t,
    }
    assert vehicles["bravo"]["last_step"] == states[-1].step // 2 and vehicles["bravo"]["t_end"] == pytest.approx(5.0)
    table = nearsub("log", "info", str(path))
    assert table.returncode == 0 and "bravo" in table.stdout and "0 .. 100" in table.stdout


def alog_postings(text: str) -> list[list[str]]:
    return [line.split(None, 3) for line in text.splitlines() if not line.startswith("%")]


def test_alog_names_each_vehicle_in_its_node_reports(fleet):
    path, result = fleet
    out = nearsub("log", "export", str(path), "--format", "alog")
    assert out.returncode == 0, out.stderr
    reports = [value for _, variable, _, value in alog_postings(out.stdout) if variable == "NODE_REPORT"]
    names = [dict(item.split("=", 1) for item in report.split(","))["NAME"] for report in reports]
    assert names.count("alfa") == len(result.topic("state")) and names.count("bravo") == len(read_states(path, "bravo"))
    bravo = [r for r in reports if "NAME=bravo" in r]
    assert f"Y={read_states(path, 'bravo')[0]['y']:g}" in bravo[0]
    assert any(variable == "EVENT_LARGE_STRAY" for _, variable, _, _ in alog_postings(out.stdout))


def read_states(path, vehicle):
    return [r.value() for r in read_log(path).records if r.topic == f"nearsub/alpha/{vehicle}/state"]


def test_alog_of_one_vehicle_is_that_vehicles_community(fleet):
    path, _ = fleet
    out = nearsub("log", "export", str(path), "--format", "alog", "--vehicle", "bravo")
    assert out.returncode == 0, out.stderr
    postings = alog_postings(out.stdout)
    assert {source for _, variable, source, _ in postings if variable == "DB_TIME"} == {"MOOSDB_bravo"}
    assert sum(variable == "NAV_X" for _, variable, _, _ in postings) == len(read_states(path, "bravo"))
    reports = [value for _, variable, _, value in postings if variable == "NODE_REPORT"]
    assert reports and all(r.startswith("NAME=bravo,") for r in reports)
    assert [value for _, variable, _, value in postings if variable == "MISSION"] == ["time_limit"]
    assert "%% LOG FILE:       bravo.alog (nearsub mission alpha)" in out.stdout


def test_an_unknown_vehicle_is_one_line_and_exit_2(fleet):
    path, _ = fleet
    out = nearsub("log", "export", str(path), "--format", "alog", "--vehicle", "charlie")
    assert out.returncode == 2 and out.stderr.strip().count("\n") == 0
    assert "--vehicle charlie" in out.stderr and "alfa, bravo" in out.stderr


def test_plot_draws_one_labelled_track_and_time_series_per_vehicle(fleet, tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    from nearsub.tools import plot

    path, _ = fleet
    figures = []
    monkeypatch.setattr(plt, "close", figures.append)  # keep the figure to look at it
    out = plot.plot_log(path, tmp_path / "fleet.png")
    assert out.stat().st_size > 10_000
    [figure] = figures
    overview, close_up, heading, *_ = figure.axes
    tracks = {line.get_label(): line.get_color() for line in overview.lines if line.get_label() in FLEET}
    assert sorted(tracks) == sorted(FLEET) and len(set(tracks.values())) == 2
    start_y = {
        name: line.get_ydata()[0] for name, line in ((ln.get_label(), ln) for ln in overview.lines) if name in FLEET
    }
    assert start_y["bravo"] - start_y["alfa"] == pytest.approx(FLEET["bravo"])
    labels = {line.get_label() for line in heading.lines}
    assert {"alfa actual", "alfa desired", "bravo actual", "bravo desired"} <= labels


def test_foxglove_gives_each_vehicle_its_frame_entity_label_and_events(fleet, tmp_path):
    from mcap.reader import make_reader

    path, _ = fleet
    target = tmp_path / "fleet-foxglove.mcap"
    out = nearsub("log", "export", str(path), "--format", "foxglove", "-o", str(target))
    assert out.returncode == 0, out.stderr
    with open(target, "rb") as f:
        messages = [(ch.topic, json.loads(m.data)) for _, ch, m in make_reader(f).iter_messages()]
    transforms = [m for topic, m in messages if topic == "/tf"]
    frames = [m["child_frame_id"] for m in transforms]
    assert frames.count("alfa") == len(read_states(path, "alfa"))
    assert frames.count("bravo") == len(read_states(path, "bravo"))
    bravo_y = [m["translation"]["y"] for m in transforms if m["child_frame_id"] == "bravo"]
    assert bravo_y == [s["y"] for s in read_states(path, "bravo")]
    entities = {e["id"]: e for topic, m in messages if topic == "/scene/uuv" for e in m["entities"]}
    assert sorted(entities) == ["alfa", "bravo"]
    assert [entities[name]["frame_id"] for name in ("alfa", "bravo")] == ["alfa", "bravo"]
    assert [entities[name]["texts"][0]["text"] for name in ("alfa", "bravo")] == ["alfa", "bravo"]
    assert entities["alfa"]["lines"][0]["color"] != entities["bravo"]["lines"][0]["color"]
    names = {m["name"] for topic, m in messages if topic == "/events"}
    assert {"helm", "bravo/helm"} <= names
    topics = {topic for topic, _ in messages}
    assert {"nearsub/alpha/alfa/state", "nearsub/alpha/bravo/state"} <= topics


def test_json_export_of_one_vehicle_keeps_its_topics_and_the_mission_wide_ones(fleet):
    path, _ = fleet
    out = nearsub("log", "export", str(path), "--format", "json", "--vehicle", "alfa")
    assert out.returncode == 0, out.stderr
    topics = {json.loads(line)["topic"] for line in out.stdout.splitlines()}
    assert "nearsub/alpha/alfa/state" in topics and "nearsub/alpha/clock/end" in topics
    assert not any("/bravo/" in topic for topic in topics)


def test_foxglove_export_of_a_mission_this_version_cannot_read_is_one_line(fleet, tmp_path):
    """A log written by another version (a mission field unknown here) is bad input, not a traceback."""
    from nearsub.common.runtime.logfile import LogWriter

    path, _ = fleet
    resolved = json.loads(read_log(path).metadata["mission"]["resolved"]) | {"convoy": [{"name": "alfa"}]}
    other = tmp_path / "other.mcap"
    writer = LogWriter(other)
    writer.metadata("mission", {"name": "alpha", "resolved": json.dumps(resolved)})
    writer.finish()
    out = nearsub("log", "export", str(other), "--format", "foxglove", "-o", str(tmp_path / "fox.mcap"))
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert "field 'convoy'" in out.stderr
