"""nearsub's MOOS sim against MOOS-IvP itself, wherever it is on PATH (built from source as the
docs/running.md says; CI cannot fetch it, so these are skipped there, saying which program is missing):
the real MOOSDB (its wire protocol, the DB going away), and MOOS-IvP's alpha mission flown by
pHelmIvP and pMarinePIDV22 with nearsub's sim in place of uSimMarineV22."""

from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pymoos2", reason="the moos extra (pip install 'nearsub[moos]')")

WAIT = 60.0  # wall seconds for start-up and a few simulated seconds at warp 10, on a loaded machine
MOOS_MISSIONS = Path(__file__).resolve().parent.parent / "missions" / "moos"
ALPHA_APPS = (
    "MOOSDB",
    "pAntler",
    "pHelmIvP",
    "pMarinePIDV22",
    "uSimMarineV22",
    "pNodeReporter",
    "uProcessWatch",
    "pLogger",
)
ALPHA_WARP = 10.0
TRACK_LINE_Y = 5.89  # m: the overtake's start and waypoint (missions/moos/overtake.bhv)
ALPHA_DURATION = 700.0  # simulated seconds: MOOS-IvP's alpha completes in about 450 (uSimMarineV22, warp 1)


OVERTAKE_DURATION = 400.0  # simulated seconds: the SDV reaches its waypoint after 240 s


def flight_budget(duration: float) -> float:
    """Wall seconds `fly` may take: start-up, `duration` at ALPHA_WARP, and pAntler's stop."""
    return 2 * WAIT + duration / ALPHA_WARP + 1.0


def need(*programs: str) -> None:
    missing = [p for p in programs if shutil.which(p) is None]
    if missing:
        pytest.skip(f"MOOS-IvP is not on PATH (missing {', '.join(missing)}); build it as docs/running.md says")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def community(tmp_path, port: int, warp: float, block: str) -> str:
    path = tmp_path / "community.moos"
    path.write_text(
        f"ServerHost = localhost\nServerPort = {port}\nCommunity = nearsub_test\nMOOSTimeWarp = {warp:g}\n"
        "LatOrigin = 43.825300\nLongOrigin = -70.330400\n\n"
        f"ProcessConfig = nearsub_sim\n{{\n{block}}}\n"
    )
    return str(path)


def client(port: int, warp: float):
    from pymoos2.core import time as moos_clock
    from pymoos2.core.MOOSCommClient import MOOSCommClient

    moos_clock.set_moos_time_warp(warp)
    probe = MOOSCommClient("localhost", port, app_name="nearsub_probe", comm_tick=20.0)
    probe.start()
    assert probe.wait_until_connected(WAIT), "the probe could not reach the MOOSDB"
    return probe


def latest(mail: dict, probe) -> dict:
    for message in probe.fetch():
        mail[message.key] = message
    return mail


def test_the_sim_against_the_real_moosdb_flies_and_leaves_when_the_db_goes(tmp_path):
    need("MOOSDB")
    port, warp = free_port(), 10.0
    path = community(tmp_path, port, warp, "  AppTick = 20\n  start_pos = x=0, y=-20, heading=180\n")
    db = subprocess.Popen(["MOOSDB", path], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    sim = subprocess.Popen([sys.executable, "-m", "nearsub", "moos", "sim", path], stderr=subprocess.PIPE, text=True)
    probe = None
    try:
        probe = client(port, warp)
        for variable in ("NAV_X", "NAV_Y", "NAV_SPEED", "NAV_HEADING", "NAV_LAT", "APPCAST"):
            probe.register(variable)
        mail: dict = {}
        deadline = time.monotonic() + WAIT
        while "NAV_X" not in latest(mail, probe) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert mail["NAV_X"].val == 0.0 and mail["NAV_Y"].val == -20.0 and mail["NAV_HEADING"].val == 180.0
        assert mail["NAV_LAT"].val == pytest.approx(43.8253 - 20.0 / 111319.5, abs=1e-6)
        probe.notify("DESIRED_THRUST", 24.0)
        probe.notify("DESIRED_RUDDER", "not-a-number")
        while (
            latest(mail, probe)["NAV_SPEED"].val < 0.5 or "run_warnings=" not in mail.get("APPCAST", mail["NAV_X"]).sval
        ) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert mail["NAV_SPEED"].val >= 0.5 and mail["NAV_Y"].val < -20.0  # southwards, at 24 % thrust
        assert "run_warnings=1:malformed DESIRED_RUDDER ignored" in mail["APPCAST"].sval
        db.send_signal(signal.SIGINT)
        db.wait(timeout=WAIT)
        _, err = sim.communicate(timeout=WAIT)
    finally:
        if probe is not None:
            probe.stop()
        for process in (sim, db):
            if process.poll() is None:
                process.kill()
                process.wait()
    assert sim.returncode == 1 and "lost the MOOSDB at localhost" in err and err.count("\n") == 1, err


def fly(folder: Path, name: str, sim: str, duration: float) -> tuple[np.ndarray, dict]:
    """missions/moos/NAME.moos + .bhv at ALPHA_WARP on a free port, with `sim` ("nearsub" or
    "uSimMarineV22") launched by pAntler, until MISSION = complete, NEARSUB_END or `duration`
    simulated seconds: the NAV_X, NAV_Y track and the last value of every variable watched."""
    folder.mkdir()
    port = free_port()
    text = (MOOS_MISSIONS / f"{name}.moos").read_text()
    text = re.sub(r"ServerPort *= *\d+", f"ServerPort = {port}", text)
    text = re.sub(r"MOOSTimeWarp *= *[\d.]+", f"MOOSTimeWarp = {ALPHA_WARP:g}", text)
    text = text.replace("mission   = ../", f"mission   = {MOOS_MISSIONS.parent}/")
    if sim == "uSimMarineV22":
        text = text.replace("  Run = nearsub ", "  //Run = nearsub ")
        text = text.replace("  //Run = uSimMarineV22", "  Run = uSimMarineV22")
    (folder / f"{name}.moos").write_text(text)
    shutil.copy(MOOS_MISSIONS / f"{name}.bhv", folder / f"{name}.bhv")
    env = os.environ | {"PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    antler = subprocess.Popen(
        ["pAntler", f"{name}.moos"],
        cwd=folder,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    track, last, probe = [], {}, None
    try:
        time.sleep(1.0)  # pAntler starts the MOOSDB first
        probe = client(port, ALPHA_WARP)
        for variable in ("NAV_X", "NAV_Y", "MISSION", "NEARSUB_END", "NEARSUB_COLLISION", "NEARSUB_CLOSE_CALL"):
            probe.register(variable)
        deadline = time.monotonic() + WAIT + duration / ALPHA_WARP
        while time.monotonic() < deadline and antler.poll() is None:
            for message in probe.fetch():
                last[message.key] = message.val if message.is_double() else message.string()
                if message.key == "NAV_Y" and "NAV_X" in last:
                    track.append((last["NAV_X"], message.val))
            if last.get("MISSION") == "complete" or "NEARSUB_END" in last:
                break
            time.sleep(0.02)
    finally:
        if probe is not None:
            probe.stop()
        os.killpg(antler.pid, signal.SIGINT)  # pAntler stops and reaps its community
        try:
            antler.wait(timeout=WAIT)
        except subprocess.TimeoutExpired:
            os.killpg(antler.pid, signal.SIGKILL)
            antler.wait()
    return np.array(track), last


def distances_to_path(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Each point's distance to the polyline `path`."""
    a, b = path[:-1], path[1:]
    ab = b - a
    length2 = np.maximum((ab**2).sum(axis=1), 1e-12)
    s = np.clip(((points[:, None, :] - a[None]) * ab[None]).sum(axis=2) / length2[None], 0.0, 1.0)
    nearest = a[None] + s[..., None] * ab[None]
    return np.sqrt(((points[:, None, :] - nearest) ** 2).sum(axis=2)).min(axis=1)


@pytest.mark.timeout(2 * flight_budget(ALPHA_DURATION))
def test_moos_ivps_alpha_completes_with_nearsubs_sim_and_its_path_is_compared_with_usimmarine(tmp_path):
    need(*ALPHA_APPS)
    ours, ours_last = fly(tmp_path / "nearsub", "alpha", "nearsub", ALPHA_DURATION)
    theirs, theirs_last = fly(tmp_path / "usim", "alpha", "uSimMarineV22", ALPHA_DURATION)
    assert theirs_last.get("MISSION") == "complete", "uSimMarineV22's alpha did not complete: the MOOS side is broken"
    assert ours_last.get("MISSION") == "complete", f"nearsub's alpha did not complete: {ours_last}"
    distance = distances_to_path(ours, theirs)
    print(
        f"alpha, nearsub's sim against uSimMarineV22's path: mean {distance.mean():.2f} m, max {distance.max():.2f} m"
    )
    # Different vehicles (the REMUS 100's dynamics, rudder limited to 15 deg, against a kinematic
    # model turning at up to 95 deg/s): they differ in the turns, not in the survey they fly.
    assert distance.max() < 25.0 and distance.mean() < 5.0, (distance.mean(), distance.max())


@pytest.mark.timeout(2 * flight_budget(OVERTAKE_DURATION) + WAIT)  # two flights and nearsub's own run
def test_the_moos_stern_overtake_ends_as_the_nearsub_mission_does(tmp_path):
    """missions/moos/overtake (pHelmIvP, pMarinePIDV22) against missions/overtake_stern_standard.toml
    (nearsub's helm and pid, in process): both collide near the stern. The autonomy differs (MOOS's
    waypoint behaviour and PID against nearsub's), so the tolerance is on where, not when."""
    need(*ALPHA_APPS)
    from nearsub.common.mission.cores import run_mission
    from nearsub.common.mission.schema import load_mission

    reference = run_mission(load_mission(MOOS_MISSIONS.parent / "overtake_stern_standard.toml"))
    collision = next(m for _, _, m in reference.messages if getattr(m, "kind", None) == "collision")
    ours, last = fly(tmp_path / "overtake", "overtake", "nearsub", OVERTAKE_DURATION)
    assert "NEARSUB_COLLISION" in last, f"no collision in MOOS: {last}"
    where = re.search(r"\(([-\d.]+), ([-\d.]+)\)", last["NEARSUB_COLLISION"]).groups()
    x_moos, y_moos = (float(v) for v in where)
    theirs = f"({collision.data['x']:.2f}, {collision.data['y']:.2f}) at t = {collision.t:.2f} s"
    print(f"stern overtake: MOOS {last['NEARSUB_COLLISION']} ({last['NEARSUB_END']}); nearsub's mission {theirs}")
    assert abs(x_moos - collision.data["x"]) < 15.0 and abs(y_moos - collision.data["y"]) < 2.0
    # The same community on uSimMarineV22 feels nothing: it holds its track-line past the hull
    # and completes, where nearsub's sim pulls it off the line into the hull.
    theirs_track, theirs_last = fly(tmp_path / "usim", "overtake", "uSimMarineV22", OVERTAKE_DURATION)
    line = TRACK_LINE_Y
    print(
        f"track-line y = {line} m: nearsub's sim came to y = {ours[:, 1].min():.2f} m; uSimMarineV22 stayed within "
        f"{np.abs(theirs_track[:, 1] - line).max():.2f} m of it, ending at x = {theirs_track[-1, 0]:.1f} m"
    )
    assert theirs_last.get("MISSION") == "complete", f"uSimMarineV22's overtake did not complete: {theirs_last}"
    assert np.abs(theirs_track[:, 1] - line).max() < 0.5
    assert line - ours[:, 1].min() > 1.5
