"""Every viewer, exporter and reader on every shipped mission (a few steps of each, run in-process
and logged under the keys the logger writes): the browser map live and replayed, Foxglove's
channels, `log info`, `log export` in each format and `log plot`. A fleet beside a submarine
(launch_two) broke each of them once."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.reader import make_reader

from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime import keys
from nearsub.common.runtime.lifecycle import ENCOUNTERS
from nearsub.common.runtime.logfile import LogWriter, read_log
from nearsub.common.runtime.messages import MissionEnd, encode
from nearsub.common.viewer.foxglove import FoxgloveScene
from nearsub.common.viewer.scene import SceneModel, feed_payload, static_scene
from nearsub.tools.cli import main
from nearsub.tools.support.log_input import mission_of_log
from nearsub.tools.view_server import ReplaySource

MISSIONS = sorted((Path(__file__).resolve().parent.parent / "missions").glob("*.toml"))
STEPS = 8  # enough for every vehicle's first states, forces and helm progress


def logged_run(mission, path: Path) -> None:
    """Run `mission` in-process and write its messages as the logger does: each vehicle's topics
    under its key chunk, each app's events under its instance, the checks between vehicles under
    theirs, and the clock's end."""
    result = run_mission(mission)
    single = None if mission.fleet else mission.vehicle_name
    writer = LogWriter(path)
    writer.metadata("mission", {"name": mission.name, "resolved": mission.model_dump_json()})
    writer.metadata("run", {"started_unix": "1800000000.000"})
    for app, leaf, message in result.messages:
        if leaf == "events":
            key = keys.events(mission.name, app if app == ENCOUNTERS else f"{app}-1")
        else:
            key = keys.vehicle_topic(mission.name, keys.split_app(app)[0] or single, leaf)
        writer.write(key, encode(message), message.t)
    t = result.steps * mission.dt
    end = MissionEnd(step=result.steps, t=t, source="clock", outcome=result.outcome, reason=result.reason)
    writer.write(keys.mission_end(mission.name), encode(end), t)
    writer.finish()


@pytest.fixture(scope="module", params=MISSIONS, ids=[p.stem for p in MISSIONS])
def run(request, tmp_path_factory):
    """(mission, its vehicles' names, the log of a few steps of it)."""
    probe = load_mission(request.param)
    mission = load_mission(request.param, [f"time_limit={STEPS * probe.dt!r}"])
    path = tmp_path_factory.mktemp(request.param.stem) / f"{mission.name}.mcap"
    logged_run(mission, path)
    return mission, [m.vehicle_name for m in mission.members()], path


def test_the_live_map_draws_every_vehicle(run):
    mission, names, path = run
    scene = static_scene(mission, source=mission.name)
    json.dumps(scene)  # what the page is sent
    assert sorted(scene["starts"]) == sorted(names)
    assert len(scene["legs"]) == sum(len(m.apps.helm.legs) for m in mission.members())
    assert scene["force_reference"] > 0
    if mission.fleet and mission.environment.submarine:  # each vehicle type's band, named after its vehicles
        by_type: dict[str, list[str]] = {}
        for member in mission.members():
            by_type.setdefault(member.vehicle_model.name, []).append(member.vehicle_name)
        assert all(f"{', '.join(same)}: " in scene["band"]["note"] for same in by_type.values())
    model = SceneModel.for_mission(mission)
    for record in read_log(path).records:
        feed_payload(model, record.topic, record.data)
    frame = model.frame()
    json.dumps(frame)
    assert [v["name"] for v in frame["vehicles"]] == sorted(names)
    assert all(v["vehicle"] is not None for v in frame["vehicles"])
    if mission.needs_surrogate:
        assert all(v["forces"] is not None for v in frame["vehicles"])


def test_the_replay_reads_the_log_and_its_mission(run):
    mission, names, path = run
    stored = mission_of_log(path)
    assert [m.vehicle_name for m in stored.members()] == names
    source = ReplaySource(path, stored)
    frame = source.model.frame()
    assert [v["name"] for v in frame["vehicles"]] == sorted(names)
    assert frame["status"]["outcome"] is not None


def test_foxglove_gets_a_frame_and_an_entity_per_vehicle(run, tmp_path, capsys):
    mission, names, path = run
    target = tmp_path / "fox.mcap"
    assert main(["log", "export", str(path), "--format", "foxglove", "-o", str(target)]) == 0
    with open(target, "rb") as f:
        messages = [(ch.topic, json.loads(m.data)) for _, ch, m in make_reader(f).iter_messages()]
    assert {m["child_frame_id"] for topic, m in messages if topic == "/tf"} == set(names)
    entities = {e["id"] for topic, m in messages if topic == "/scene/uuv" for e in m["entities"]}
    assert entities == set(names)
    live = FoxgloveScene(mission, 0)  # what `nearsub foxglove` serves from the same messages
    assert [topic for topic, _, _ in live.static_updates(0.0)] == ["/scene/mission"]


def test_the_log_commands_read_every_vehicle(run, tmp_path, capsys):
    mission, names, path = run
    assert main(["log", "info", str(path), "--json"]) == 0
    assert sorted(json.loads(capsys.readouterr().out)["vehicles"]) == sorted(names)
    assert main(["log", "export", str(path), "--format", "json"]) == 0
    topics = {json.loads(line)["topic"] for line in capsys.readouterr().out.splitlines()}
    assert {keys.vehicle_topic(mission.name, name, "state") for name in names} <= topics
    assert main(["log", "export", str(path), "--format", "csv", "-o", str(tmp_path / "csv")]) == 0
    assert {f"{keys.vehicle_topic(mission.name, n, 'state').replace('/', '_')}.csv" for n in names} <= {
        p.name for p in (tmp_path / "csv").iterdir()
    }
    for name in names:
        assert main(["log", "export", str(path), "--format", "alog", "--vehicle", name]) == 0
        assert "NAV_X" in capsys.readouterr().out
    assert main(["log", "plot", str(path), "-o", str(tmp_path / "plot.png")]) == 0
    assert (tmp_path / "plot.png").stat().st_size > 0
