"""The MOOS-IvP side of `nearsub bench pipeline`: the headless rewrite of the alpha files, what is
read from them and from an alog, and the skip without MOOS-IvP (no MOOS-IvP needed here)."""

from __future__ import annotations

import math

import pytest

from nearsub.common.mission.schema import load_mission
from nearsub.tools import moos_alpha
from nearsub.tools.commands.bench import DEFAULT_MISSION

MOOS_FILE = """\
ServerHost   = localhost
MOOSTimeWarp = 1
ProcessConfig = ANTLER
{
  Run = MOOSDB        @ NewConsole = false
  Run = pHelmIvP      @ NewConsole = false
  Run = pMarineViewer\t@ NewConsole = false
  Run = pRealm        @ NewConsole = false
}
ProcessConfig = uSimMarineV22
{
  start_pos     = x=0, y=-20, heading=180, speed=0
}
"""

BHV_FILE = """\
initialize   DEPLOY = false
initialize   RETURN = false
Behavior = BHV_Waypoint
{
  name    = survey
  polygon = 60,-40:60,-160:150,-160:180,-100:150,-40
}
Behavior = BHV_Waypoint
{
  name   = home
  points = 0,-20
}
Behavior = BHV_ConstantSpeed
{
  speed = 0.5
}
"""


def test_headless_moos_drops_the_gui_apps_and_sets_the_warp():
    kept = [line for line in MOOS_FILE.splitlines(keepends=True) if "Run = p" not in line or "pHelmIvP" in line]
    expected = "".join(kept).replace("MOOSTimeWarp = 1\n", "MOOSTimeWarp = 25\n")
    assert moos_alpha.headless_moos(MOOS_FILE, 25.0) == expected
    assert "Run = MOOSDB" in expected and "MOOSTimeWarp = 25" in expected
    with pytest.raises(ValueError, match="MOOSTimeWarp"):
        moos_alpha.headless_moos("ServerPort = 9000\n", 25.0)


def test_headless_bhv_deploys_at_start():
    text = moos_alpha.headless_bhv(BHV_FILE)
    assert text.splitlines()[:3] == [
        "initialize DEPLOY = true",
        "initialize MOOS_MANUAL_OVERRIDE = false",
        "initialize   RETURN = false",
    ]
    assert text.endswith(BHV_FILE.split("\n", 1)[1])
    with pytest.raises(ValueError, match="DEPLOY"):
        moos_alpha.headless_bhv("initialize RETURN = false\n")


def test_the_waypoints_and_start_read_from_the_files_match_nearsubs_alpha(tmp_path):
    assert moos_alpha.waypoint_legs(BHV_FILE) == [
        [(60.0, -40.0), (60.0, -160.0), (150.0, -160.0), (180.0, -100.0), (150.0, -40.0)],
        [(0.0, -20.0)],
    ]
    assert moos_alpha.start_pose(MOOS_FILE) == {"x": 0.0, "y": -20.0, "heading": 180.0, "speed": 0.0}
    (tmp_path / "alpha.moos").write_text(MOOS_FILE)
    (tmp_path / "alpha.bhv").write_text(BHV_FILE)
    mission = load_mission(DEFAULT_MISSION)
    assert moos_alpha.same_mission(tmp_path, mission) == []
    (tmp_path / "alpha.bhv").write_text(BHV_FILE.replace("points = 0,-20", "points = 0,-25"))
    (difference,) = moos_alpha.same_mission(tmp_path, mission)
    assert difference.startswith("waypoints:")


def test_parse_alog_reads_the_run_phase_and_the_final_position():
    alog = """\
%% LOGSTART           44904428626.73185
10.0 IVPHELM_STATE pHelmIvP PARK
12.5 IVPHELM_STATE pHelmIvP DRIVE
13.0 NAV_X uSimMarineV22 0.5
13.0 NAV_Y uSimMarineV22 -20.5
13.2 PID_STALE pMarinePIDV22 Stale NavSpd:2.9
12.9 IVPHELM_STATE pHelmIvP DRIVE
400.0 NAV_X uSimMarineV22 1.25
400.0 NAV_Y uSimMarineV22 -19.5
401.5 MISSION pHelmIvP:1335:waypt_return complete
402.0 NAV_X uSimMarineV22 9.0
"""
    parsed = moos_alpha.parse_alog(alog)
    assert parsed == {"drive": 12.5, "end": 401.5, "x": 1.25, "y": -19.5, "pid_stale": 1}
    assert math.isnan(moos_alpha.parse_alog("12.5 IVPHELM_STATE pHelmIvP DRIVE\n")["x"])


def test_without_moos_on_path_the_comparison_is_skipped_in_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PATH", str(tmp_path))
    result = moos_alpha.compare(DEFAULT_MISSION, repeats=1, verbose=True)
    assert result == {
        "ran": False,
        "reason": f"MOOS-IvP not on PATH (missing {', '.join(moos_alpha.MOOS_APPS)}): comparison skipped",
    }
    moos_alpha.print_comparison(result)
    out, err = capsys.readouterr()
    assert out == f"MOOS-IvP alpha at warp 25 and 50: {result['reason']}\n" and err == ""
