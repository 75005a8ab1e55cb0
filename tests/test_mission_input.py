"""Hostile mission input: non-finite and absurd numbers, bad bytes, bad endpoints, and errors that
name where the bad value came from (the file or a --set override)."""

import pytest

from conftest import ALPHA, nearsub
from nearsub.common.mission.schema import MissionError, load_mission


@pytest.mark.parametrize(
    "override, field",
    [
        ("start.x=nan", "start.x"),
        ("start.psi_deg=inf", "start.psi_deg"),
        ("environment.u_sub=-inf", "environment.u_sub"),
        ("step_timeout=nan", "step_timeout"),
        ("warp=1e308", "warp"),  # finite, but the clock's pacing would overflow
        ("time_limit=1e307", "time_limit"),  # finite, but not its number of steps
        ("start.x=1e300", "start.x"),
        ("start.speed=1e9", "start.speed"),
        ("apps.helm.legs=[{points=[[1e12, 0.0]], speed=1.5}]", "apps.helm.legs.0.points.0.0"),
        ("apps.helm.legs=[{points=[[nan, 0.0]], speed=1.5}]", "apps.helm.legs.0.points.0.0"),
        ("apps.helm.legs=[{points=[[0.0, 0.0]], speed=inf}]", "apps.helm.legs.0.speed"),
    ],
)
def test_non_finite_and_absurd_numbers_are_refused_naming_the_override(override, field):
    with pytest.raises(MissionError) as info:
        load_mission(ALPHA, [override])
    message = str(info.value)
    assert message.startswith(f"--set {override}:"), message
    assert f"field '{field}'" in message


TWO = ALPHA.parent / "launch_two.toml"


@pytest.mark.parametrize(
    ("mission", "override", "says"),
    [
        (TWO, "vehicles=1", "--set vehicles=1: field 'vehicles' = 1: "),  # the value given, not the names
        (TWO, "vehicles=[]", "--set vehicles=[]: field 'vehicles' = []: leave [[vehicles]] out for a single-vehicle"),
        # Deeper than the bad field, and in the fleet vehicles' copies of [apps.*]: still the --set.
        (TWO, "apps.helm.period.x=1", "--set apps.helm.period.x=1: field 'vehicles.auv1.apps.helm.period' = "),
        (ALPHA, "apps..helm=1", "--set 'apps..helm=1': empty part in key 'apps..helm'"),
        (ALPHA, "vehicle=3", "--set vehicle=3: field 'vehicle' = 3: Value error, expected a vehicle name"),
    ],
)
def test_an_override_error_names_the_override_and_the_value_given(mission, override, says):
    with pytest.raises(MissionError) as info:
        load_mission(mission, [override])
    assert str(info.value).startswith(says), str(info.value)
    assert "function-after" not in str(info.value)  # no member of pydantic's union


def test_a_missing_field_is_named_without_its_parent_as_the_value(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text('name = "m"\n')
    with pytest.raises(MissionError) as info:
        load_mission(path)
    assert str(info.value) == f"{path}: field 'apps': Field required"


def test_a_bad_value_in_the_file_names_the_file(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(ALPHA.read_text().replace("x = 0.0", "x = nan", 1))
    with pytest.raises(MissionError) as info:
        load_mission(path, ["name=other"])
    assert str(info.value).startswith(f"{path}:") and "field 'start.x' = nan" in str(info.value)


def test_non_utf8_bytes_are_one_line_naming_the_offset(tmp_path):
    path = tmp_path / "m.toml"
    path.write_bytes(ALPHA.read_bytes() + b"\n# caf\xe9\n")
    with pytest.raises(MissionError) as info:
        load_mission(path)
    assert "not UTF-8 text (byte 0xe9 at offset" in str(info.value)


@pytest.mark.parametrize("endpoint", ["192.0.2.10:7447", "tcp/host", "tcp/127.0.0.1:99999", "http://x:1"])
def test_a_malformed_endpoint_is_refused(endpoint):
    with pytest.raises(MissionError) as info:
        load_mission(ALPHA, [f'network.connect=["{endpoint}"]'])
    assert "network.connect" in str(info.value) and endpoint in str(info.value)


def test_valid_endpoints_are_kept():
    mission = load_mission(ALPHA, ['network.connect=["tcp/192.0.2.10:7447", "tcp/[::1]:7447"]'])
    assert mission.network.connect == ["tcp/192.0.2.10:7447", "tcp/[::1]:7447"]


def test_launch_of_a_nan_start_exits_2_with_one_line(tmp_path, runtime_dir):
    logs = tmp_path / "logs"
    result = nearsub("launch", str(ALPHA), "--set", "start.x=nan", "--log", str(logs))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "start.x" in lines[0] and "Traceback" not in result.stderr
    assert not logs.exists() or list(logs.iterdir()) == []  # nothing started, no half-empty log folder


def test_a_bad_value_from_an_included_file_names_that_file(tmp_path):
    text = "\n".join(line for line in ALPHA.read_text().splitlines() if not line.startswith("dt ="))
    (tmp_path / "top.toml").write_text('include = ["middle.toml"]\n' + text)
    (tmp_path / "middle.toml").write_text('include = ["bottom.toml"]\n')
    (tmp_path / "bottom.toml").write_text("dt = -1\n")
    with pytest.raises(MissionError) as info:
        load_mission(tmp_path / "top.toml")
    assert str(info.value) == f"{tmp_path / 'bottom.toml'}: field 'dt' = -1: Input should be greater than 0"
