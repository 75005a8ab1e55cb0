"""Physics in missions: vehicles, waves, collisions, divergence, custom vehicles, validate."""

import pytest

from conftest import ALPHA, ROOT, nearsub
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import MissionError, load_mission
from nearsub.common.physics.hull import R_SUB, explorer_cb_from_nose
from nearsub.common.physics.vehicles import REMUS100

WAVES = ROOT / "missions" / "waves_ss5.toml"

# A REMUS heading straight at the submarine's side (hull radius 5.18 m at mid-body).
RAMMING = [
    "name=ram",
    "environment.submarine=true",
    "start.x=0",
    "start.y=15",
    "start.psi_deg=-90",
    "start.speed=1.2",
    "apps.helm.legs=[{points = [[0.0, -15.0]], speed = 1.2}]",
    "time_limit=60",
]


def events(result, kind):
    return [m for _, leaf, m in result.messages if leaf == "events" and m.kind == kind]


@pytest.mark.parametrize("vehicle", ["remus100", "nps_auv_ii", "sdv"])
def test_alpha_with_each_vehicle(vehicle):
    result = run_mission(load_mission(ALPHA, [f"vehicle={vehicle}"]))
    assert result.outcome == "completed" and len(events(result, "waypoint")) == 6


def test_ramming_the_submarine_is_a_collision():
    result = run_mission(load_mission(ALPHA, RAMMING))
    assert result.outcome == "collision"
    final = result.topic("state")[-1]
    nose = final.y - explorer_cb_from_nose(REMUS100.length, REMUS100.diameter)
    assert R_SUB - 0.05 < nose <= R_SUB + 0.01  # the nose meets the hull within one step (6 cm)
    assert len(events(result, "close_call")) == 1 and len(events(result, "collision")) == 1


def test_collision_is_a_normal_ending_for_the_launcher(launches, community):
    code, summary, err = launches.run(ALPHA, *sum((["--set", o] for o in RAMMING), []), "--set", f"name={community}")
    assert code == 0, err
    assert summary["outcome"] == "collision" and summary["events"]["collision"] == 1


def test_divergence_ends_the_mission_with_a_clear_message(launches, community):
    code, summary, err = launches.run(ALPHA, "--set", f"name={community}", "--set", "apps.sim.divergence_speed=1.0")
    assert code == 1
    assert summary["outcome"] == "diverged" and "u = 1.0" in summary["reason"]
    assert "Traceback" not in err


def test_waves_push_the_uuv_but_it_keeps_the_track():
    waves = run_mission(load_mission(WAVES))
    calm = run_mission(load_mission(WAVES, ["environment.sea_state=0"]))
    assert waves.outcome == calm.outcome == "completed"
    worst_waves = max(m.cross_track for m in waves.topic("helm"))
    worst_calm = max(m.cross_track for m in calm.topic("helm"))
    assert worst_calm < 0.05 and 0.2 < worst_waves < 2.0
    sides = {m.y > 20.0 for m in waves.topic("state")[100:]}
    assert sides == {True, False}  # it oscillates about the track-line


def test_custom_vehicle_inline_and_its_errors(tmp_path):
    fields = REMUS100.model_dump()
    fields.update(name="remus_heavy", mass=40.0)
    mission = load_mission(ALPHA, [f"vehicle={_toml_table(fields)}", "time_limit=20"])
    assert mission.vehicle_model.mass == 40.0 and run_mission(mission).outcome == "time_limit"
    fields["Izz"] = -3.0
    with pytest.raises(MissionError) as info:
        load_mission(ALPHA, [f"vehicle={_toml_table(fields)}"])
    assert "vehicle" in str(info.value) and "Izz" in str(info.value) and "-3.0" in str(info.value)


# The whole `nearsub validate` (every scenario mission with the LF in the loop): minutes; the
# default run covers its parts in test_validation.py and test_scenarios.py.
@pytest.mark.slow
@pytest.mark.timeout(900)
def test_validate_passes():
    result = nearsub("validate", "--json", timeout=120)
    assert result.returncode == 0, result.stdout[-2000:]


def _toml_table(values: dict) -> str:
    def value(v):
        if isinstance(v, dict):
            return _toml_table(v)
        if isinstance(v, str):
            return f'"{v}"'
        if v == float("inf"):
            return "inf"
        return repr(v)

    return "{" + ", ".join(f"{k} = {value(v)}" for k, v in values.items() if v is not None) + "}"
