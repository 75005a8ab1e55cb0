"""`nearsub poke MISSION=complete` ends the mission through the clock's normal end request, at the
step the helm applies the poke (MOOS-IvP: uPokeDB posting the variable uQueryDB waits for)."""

from helpers import finish, log_path, poke_while_paused, run_with_poke
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.logfile import read_log

MISSION = """
name = "pokeend"
time_limit = 60.0
pause_at_step = 100
[start]
speed = 1.0
[environment]
submarine = false
[[apps.helm.behaviours]]
type = "constant_heading"
name = "east"
heading_deg = 0.0
"""


def test_a_poke_of_mission_complete_ends_the_mission_at_the_helm_step_in_process(tmp_path):
    mission = load_mission_text(tmp_path)
    result = run_with_poke(mission, {"MISSION": "complete"}, at_step=101)
    # The helm runs every 5 steps: the poke due at 101 is applied at 105, the last step run.
    assert (result.outcome, result.steps) == ("completed", 106)
    assert "MISSION = complete (poked)" in result.reason


def test_nearsub_poke_mission_complete_ends_a_running_mission(launches, community, tmp_path):
    mission, process = poke_while_paused(launches, write_mission(tmp_path), community, "MISSION=complete")
    # Ending takes at most a few steps, each within step_timeout, then the apps' shutdown.
    code, summary, err = finish(process, timeout=mission.startup_timeout + 10 * mission.step_timeout)
    assert code == 0, err
    assert (summary["outcome"], summary["steps"]) == ("completed", 101), summary
    assert "MISSION = complete (poked)" in summary["reason"]
    records = read_log(log_path(summary)).records
    [request] = [r.value() for r in records if r.topic.endswith("/clock/ack/helm") and r.value()["end"]]
    assert (request["step"], request["end"]) == (100, "completed")
    [end] = [r.value() for r in records if r.topic.endswith("/clock/end")]
    assert (end["step"], end["outcome"]) == (101, "completed")  # MissionEnd carries the steps run


def test_a_poke_of_a_fleet_mission_file_must_name_one_of_its_vehicles(monkeypatch, capsys, tmp_path):
    """A mission file with `[[vehicles]]` (its entries as the schema dumps them) has no single
    vehicle to poke by default."""
    import argparse

    from nearsub.common.mission import schema
    from nearsub.tools.commands import poke, tap

    mission = load_mission_text(tmp_path)
    dumped = mission.model_dump() | {"vehicles": [{"name": "alfa"}, {"name": "bravo"}]}
    fleet = type("Fleet", (), {"name": mission.name, "vehicle_name": "remus100", "model_dump": lambda self: dumped})
    monkeypatch.setattr(schema, "load_mission", lambda path: fleet())
    for vehicle, text in ((None, "give --vehicle NAME"), ("zulu", "--vehicle zulu: not a vehicle of")):
        args = argparse.Namespace(
            mission=str(tmp_path / "pokeend.toml"), assignments=["X=1"], vehicle=vehicle, connect=None, credentials=None
        )
        assert poke.run(args) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"nearsub poke: {text}") and "(its vehicles: alfa, bravo)" in err, err
    # A fleet of one: its vehicle is the default, as for a mission without [[vehicles]].
    dumped["vehicles"] = [{"name": "solo"}]
    published = []
    monkeypatch.setattr(tap, "tap_pub", lambda pub: published.append(pub.key) or 0)
    args = argparse.Namespace(
        mission=str(tmp_path / "pokeend.toml"), assignments=["X=1"], vehicle=None, connect=None, credentials=None
    )
    assert poke.run(args) == 0 and published == [f"nearsub/{mission.name}/solo/poke"]


def write_mission(folder):
    path = folder / "pokeend.toml"
    path.write_text(MISSION)
    return path


def load_mission_text(folder):
    return load_mission(write_mission(folder))
