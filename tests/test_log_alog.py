"""`nearsub log export --format alog`: a file MOOS-IvP's alog tools read (docs/design.md, "MOOS-IvP
conventions"). The checks follow the parsing rules of moos-ivp's `lib_logutils/LogUtils.cpp`:
`%` lines are comments, LOGSTART stands within the first five lines, every other line is
`TIME VARIABLE SOURCE VALUE` with a numeric time and a non-empty value."""

import math
import shutil
import subprocess

import pytest
from logsample import STARTED_UNIX, write_sample_log

from conftest import nearsub
from nearsub.common.physics.vehicles import get_vehicle
from nearsub.common.runtime.alog import compass_deg


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    folder = tmp_path_factory.mktemp("alog")
    result = write_sample_log(folder / "alpha.mcap", shuffle=True)
    target = folder / "alpha.alog"
    out = nearsub("log", "export", str(folder / "alpha.mcap"), "--format", "alog", "-o", str(target))
    assert out.returncode == 0, out.stderr
    lines = target.read_text().splitlines()
    body = [line.split(None, 3) for line in lines if not line.startswith("%")]
    return result, lines, body


def postings(body, variable):
    return [(float(t), source, value) for t, var, source, value in body if var == variable]


def test_header_is_plogger_banner_with_logstart(exported):
    _, lines, _ = exported
    assert lines[0].startswith("%%%%") and lines[4].startswith("%%%%")
    assert lines[1].startswith("%% LOG FILE:") and lines[2].startswith("%% FILE OPENED ON  ")
    logstart = [line for line in lines[:5] if "LOGSTART" in line]
    assert len(logstart) == 1 and float(logstart[0].split()[-1]) == pytest.approx(STARTED_UNIX, abs=1e-3)


def test_every_line_has_time_variable_source_value(exported):
    _, lines, body = exported
    assert all(line.startswith("%%") for line in lines[: len(lines) - len(body)])
    for fields in body:
        assert len(fields) == 4, fields
        float(fields[0])
        assert fields[1].isupper() and fields[3].strip()


def test_lines_are_sorted_by_time_although_the_log_is_not(exported):
    _, _, body = exported
    times = [float(fields[0]) for fields in body]
    assert times == sorted(times) and times[-1] == pytest.approx(10.0)


def test_nav_variables_one_per_line_in_compass_degrees(exported):
    result, _, body = exported
    states = sorted(result.topic("state"), key=lambda s: s.t)
    assert [float(v) for _, _, v in postings(body, "NAV_X")] == pytest.approx([s.x for s in states], abs=1e-6)
    assert [float(v) for _, _, v in postings(body, "NAV_Y")] == pytest.approx([s.y for s in states], abs=1e-6)
    assert [float(v) for _, _, v in postings(body, "NAV_SPEED")] == pytest.approx([s.u for s in states], abs=1e-6)
    headings = [float(v) for _, _, v in postings(body, "NAV_HEADING")]
    assert headings[0] == pytest.approx(180.0)  # alpha starts at psi = -90 deg: heading south
    assert headings == pytest.approx([(90 - math.degrees(s.psi)) % 360 for s in states], abs=1e-6)
    assert all(0 <= h < 360 for h in headings)
    yaw = [float(v) for _, _, v in postings(body, "NAV_YAW")]
    assert yaw[0] == pytest.approx(-math.pi, abs=1e-6)  # uSimMarine: -radians(angle180(heading))


def test_compass_conversion():
    assert compass_deg(0.0) == pytest.approx(90.0)  # psi along +x (east)
    assert compass_deg(math.pi / 2) == pytest.approx(0.0)  # +y (north)
    assert compass_deg(-math.pi / 2) == pytest.approx(180.0)
    assert compass_deg(math.pi) == pytest.approx(270.0)
    assert 0 <= compass_deg(math.radians(90 + 1e-14)) < 360


def test_node_report_and_desired_values(exported):
    result, _, body = exported
    reports = postings(body, "NODE_REPORT")
    assert len(reports) == len(result.topic("state"))
    fields = dict(item.split("=", 1) for item in reports[0][2].split(","))
    assert fields["NAME"] == "alpha" and fields["TYPE"] == "UUV" and fields["HDG"] == "180"
    assert float(fields["X"]) == 0 and float(fields["Y"]) == -20 and "SPD" in fields
    assert float(fields["TIME"]) == pytest.approx(STARTED_UNIX, abs=1e-3)
    assert float(postings(body, "NODE_REPORT")[-1][2].split("TIME=")[1].split(",")[0]) == pytest.approx(
        STARTED_UNIX + 10.0, abs=1e-3
    )
    desired = sorted(result.topic("desired"), key=lambda d: d.t)
    heading = [float(v) for _, _, v in postings(body, "DESIRED_HEADING")]
    assert heading == pytest.approx([compass_deg(d.psi_d) for d in desired], abs=1e-6)
    assert [float(v) for _, _, v in postings(body, "DESIRED_SPEED")] == pytest.approx([d.u_d for d in desired])
    inputs = sorted(result.topic("input"), key=lambda m: m.t)
    rudder = [float(v) for _, _, v in postings(body, "DESIRED_RUDDER")]
    assert rudder == pytest.approx([math.degrees(m.delta_r) for m in inputs], abs=1e-6)
    thrust = [float(v) for _, _, v in postings(body, "DESIRED_THRUST")]
    limit = get_vehicle("remus100").max_thrust  # pMarinePID posts the percent of the thrust limit
    assert thrust == pytest.approx([100 * m.X_prop / limit for m in inputs], abs=1e-6)
    assert max(abs(v) for v in thrust) <= 100.0
    assert {source for _, source, _ in postings(body, "DESIRED_RUDDER")} == {"pid"}


def test_events_and_controls_are_text_variables(exported):
    result, _, body = exported
    events = result.topic("events")
    for kind in {e.kind for e in events}:
        posted = sorted((t, v) for t, _, v in postings(body, f"EVENT_{kind.upper()}"))
        assert posted == sorted((round(e.t, 3), e.detail or e.kind) for e in events if e.kind == kind)
    assert postings(body, "CONTROL_REQUEST") == [(2.0, "tap", "target=clock,cmd=pause")]
    assert postings(body, "INVALID_MESSAGE") == [(10.0, "logger", "nearsub/alpha/remus100/state")]
    db_time = postings(body, "DB_TIME")
    assert [t for t, _, _ in db_time] == [float(s) for s in range(11)] and db_time[0][1] == "MOOSDB_alpha"


@pytest.mark.skipif(
    shutil.which("alogsort") is None or shutil.which("aloggrep") is None,
    reason="MOOS-IvP's alogsort and aloggrep are not on PATH (see docs/running.md's MOOS-IvP build)",
)
def test_moos_ivps_own_tools_read_it(exported, tmp_path):
    """Where MOOS-IvP is installed: alogsort finds nothing to re-sort and aloggrep keeps the NAV_*
    track that alogview draws."""
    source = tmp_path / "alpha.alog"
    source.write_text("\n".join(exported[1]) + "\n")
    sorted_alog = tmp_path / "sorted.alog"
    subprocess.run(["alogsort", str(source), str(sorted_alog)], check=True, capture_output=True)
    assert sorted_alog.read_text() == source.read_text()
    nav = tmp_path / "nav.alog"
    subprocess.run(
        ["aloggrep", str(source), "NAV_X", "NAV_Y", "NAV_HEADING", str(nav)], check=True, capture_output=True
    )
    kept = {line.split()[1] for line in nav.read_text().splitlines() if line and not line.startswith("%")}
    assert kept == {"NAV_X", "NAV_Y", "NAV_HEADING"}
