import pytest

from conftest import ALPHA, nearsub
from nearsub.common.mission.schema import MissionError, load_mission


def write(tmp_path, text):
    path = tmp_path / "m.toml"
    path.write_text(text)
    return path


def test_alpha_loads_with_the_moos_parameters():
    mission = load_mission(ALPHA)
    survey, home = mission.apps.helm.legs
    assert survey.points[0] == (60.0, -40.0) and len(survey.points) == 5
    assert (survey.speed, survey.lead, survey.capture_radius, survey.slip_radius) == (1.2, 8.0, 5.0, 15.0)
    assert home.points == [(0.0, -20.0)] and home.speed == 2.0 and home.capture_radius == 2.0
    assert mission.start.psi_deg == -90.0  # compass 180 -> psi = 90 - 180


def test_overrides_are_typed():
    mission = load_mission(ALPHA, ["dt=0.1", "vehicle=sdv", "apps.helm.period=2", "name=other"])
    assert mission.dt == 0.1 and mission.vehicle_name == "sdv" and mission.apps.helm.period == 2
    assert mission.name == "other"


@pytest.mark.parametrize(
    "edit, field, value",
    [
        (lambda t: t.replace("dt = 0.05", 'dt = "fast"'), "dt", "fast"),
        (lambda t: t + "\nwarp_drive = 3\n", "warp_drive", "3"),
        (lambda t: t.replace('name = "alpha"\n', ""), "name", ""),
        (lambda t: t.replace("speed = 1.2", "speed = -1.2"), "speed", "-1.2"),
    ],
)
def test_broken_mission_names_file_field_and_value(tmp_path, edit, field, value):
    path = write(tmp_path, edit(ALPHA.read_text()))
    with pytest.raises(MissionError) as info:
        load_mission(path)
    text = str(info.value)
    assert str(path) in text and field in text and value in text
    assert "\n" not in text


def test_unknown_vehicle_is_named(tmp_path):
    with pytest.raises(MissionError, match="submarine9"):
        load_mission(ALPHA, ["vehicle=submarine9"])


def test_launch_exits_2_with_one_line_for_a_broken_mission(tmp_path, runtime_dir):
    path = write(tmp_path, ALPHA.read_text().replace("dt = 0.05", 'dt = "fast"'))
    result = nearsub("launch", str(path), "--log", str(tmp_path / "logs"))
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and str(path) in lines[0] and "'dt'" in lines[0] and "fast" in lines[0]
    assert not (tmp_path / "logs").exists() or not any((tmp_path / "logs").iterdir())


def test_invalid_toml_is_reported(tmp_path):
    path = write(tmp_path, "name = \n")
    with pytest.raises(MissionError, match="not valid TOML"):
        load_mission(path)


def test_a_check_of_the_whole_mission_says_its_reason_alone():
    """A swap's `--with` that breaks a check across fields (a modified waypoints helm with no
    submarine speed) names the reason in one short line, not the resolved mission it checked."""
    from nearsub.common.mission.schema import apply_overrides, mission_from_dict

    resolved = load_mission(ALPHA).model_dump(mode="json")
    with pytest.raises(MissionError) as caught:
        mission_from_dict(apply_overrides(resolved, ["apps.helm.behaviour=modified_waypoints"]), "--with")
    text = str(caught.value)
    assert text.startswith("--with: apps.helm.behaviour = 'modified_waypoints'")
    assert "needs environment.u_sub > 0 (got 0.0)" in text
    assert "\n" not in text and resolved["description"] not in text and len(text) < 200


def test_validate_checks_mission_files_without_running_them(tmp_path, capsys):
    """`nearsub validate FILE` (and a shipped mission's name) reads and validates as `launch`
    would, one line each; a misspelt field gets the names it may stand for (difflib over the
    schema's fields at its place), and a bad file is exit 2."""
    from nearsub.tools.cli import main

    typo = write(tmp_path, ALPHA.read_text().replace("time_limit =", "time_limt =").replace("period = ", "periodd = "))
    assert main(["validate", str(ALPHA), "launch_two"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"{ALPHA}: ok: mission alpha, remus100, no submarine, 900 s in steps of 0.05 s"
    assert out[1].endswith("launch_two, auv1 (remus100), auv2 (nps_auv_ii), near a submarine, 160 s in steps of 0.05 s")
    assert main(["validate", str(typo)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"nearsub validate: {typo}: ")
    assert "field 'time_limt' = 900.0: Extra inputs are not permitted (did you mean 'time_limit'?)" in line
    assert "(did you mean 'period'?)" in line
    assert main(["validate", "alph"]) == 2
    assert "alph: no such mission file, nor a shipped mission (shipped: alpha, " in capsys.readouterr().err


def test_launch_takes_a_shipped_mission_by_name(tmp_path, runtime_dir, community):
    result = nearsub("launch", "alpha", "--until", "1", "--set", f"name={community}", "--log", str(tmp_path), "--json")
    assert result.returncode == 0, result.stderr
    assert '"outcome": "time_limit"' in result.stdout
