"""Tap, swap and the clock controls against running missions."""

import json
import math
import os
import pty
import re
import subprocess
import sys
import time

import pytest

from conftest import ALPHA, nearsub
from helpers import finish, log_path, per_topic, wait_paused, wait_registered
from nearsub.common.mission.cores import build_cores
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.lifecycle import Schedule, run_inprocess
from nearsub.common.runtime.logfile import read_log
from nearsub.common.runtime.messages import Desired, encode

pytestmark = pytest.mark.timeout(180)


def test_tap_echo_and_hz_on_a_running_mission(launches, community):
    process = launches.start(ALPHA, "--set", f"name={community}", "--warp", "5", "--until", "60")
    wait_registered(community)
    echo = nearsub("tap", "echo", community, "*/state", "--count", "5", "--field", "u", "--timeout", "30")
    assert echo.returncode == 0, echo.stderr
    lines = [json.loads(line) for line in echo.stdout.splitlines()]
    assert len(lines) == 5 and all(line["key"] == f"nearsub/{community}/remus100/state" for line in lines)
    assert all(isinstance(line["value"], float) for line in lines)
    times = [line["t"] for line in lines]
    assert times == sorted(times)

    hz = nearsub("tap", "hz", community, "**", "--duration", "3", "--json")
    assert hz.returncode == 0, hz.stderr
    rates = {}
    for line in hz.stdout.splitlines():
        item = json.loads(line)
        rates[item["key"].split("/", 2)[2]] = item["hz"]
    assert rates["remus100/state"] == pytest.approx(20.0, rel=0.01)  # dt = 0.05 s of simulated time
    assert rates["remus100/desired"] == pytest.approx(4.0, rel=0.01)  # helm period 5

    listed = nearsub("tap", "list", community, "--json")
    assert listed.returncode == 0, listed.stderr
    apps = json.loads(listed.stdout)["apps"]
    for role in ("helm", "pid", "sim", "clock", "logger"):
        assert any(f"/alive/{role}/" in key for key in apps), (role, apps)
    topics = {row["key"].split("/", 2)[2]: row for row in json.loads(listed.stdout)["topics"]}
    assert topics["remus100/state"]["type"] == "State"
    assert topics["remus100/state"]["hz"] == pytest.approx(20.0, rel=0.01)  # over the default 1 s sample
    code, summary, err = finish(process)
    assert code == 0 and summary["outcome"] == "time_limit", err


def subset(data: dict, *names: str) -> dict:
    return {name: data[name] for name in names}


@pytest.mark.parametrize(
    ("app", "wait_for_the_pause"), [("helm", False), ("helm", True), ("pid", False), ("sim", False)]
)
def test_swap_at_a_fixed_step_keeps_the_trajectory(launches, community, app, wait_for_the_pause):
    """Swapping an app for an identical one mid-mission must not change a single bit, whether
    the swap request reaches the clock before or after it has paused at the step. Step 1000 is a
    helm step: the new pid's desired and the new sim's input are made after the pause."""
    process = launches.start(ALPHA, "--set", f"name={community}", "--set", "pause_at_step=1000", "--until", "150")
    wait_registered(community)
    if wait_for_the_pause:
        assert subset(wait_paused(community), "step", "paused") == {"step": 1000, "paused": True}
    settings = ["--with", "behaviour=waypoints"] if app == "helm" else []
    swap = nearsub("swap", community, app, "--at-step", "1000", *settings, "--json")
    assert swap.returncode == 0, swap.stderr
    result = json.loads(swap.stdout)
    assert result["step"] == 1000 and result["old"] == f"{app}-1" and result["new"] == f"{app}-2"
    code, summary, err = finish(process)
    assert code == 0, err
    assert summary["swaps"] == [{"old": f"{app}-1", "new": f"{app}-2", "step": 1000}]

    mission = load_mission(ALPHA, [f"name={community}", "time_limit=150"])
    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    logged = per_topic(log_path(summary))
    for leaf in ("state", "desired", "input"):
        assert logged[f"remus100/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf
    events = [r.value() for r in read_log(log_path(summary)).records if r.topic.endswith("/events/launcher")]
    swaps = [e for e in events if e["kind"] == "swap"]
    assert len(swaps) == 1 and swaps[0]["step"] == 1000 and f"{app}-1 -> {app}-2" in swaps[0]["detail"]


def test_swap_rejects_a_bad_setting_and_the_mission_goes_on(launches, community):
    process = launches.start(ALPHA, "--set", f"name={community}", "--warp", "10", "--until", "40")
    wait_registered(community)
    swap = nearsub("swap", community, "helm", "--with", "period=0")
    assert swap.returncode == 2, swap.stderr  # bad input: one line naming the setting and its value
    assert swap.stderr.startswith("nearsub swap: --with: field 'apps.helm.period' = 0: ")
    assert len(swap.stderr.strip().splitlines()) == 1
    refused = nearsub("swap", community, "logger")
    assert refused.returncode == 2 and refused.stderr.startswith("nearsub swap: cannot swap 'logger': only helm, pid")
    code, summary, err = finish(process)
    assert code == 0 and summary["outcome"] == "time_limit" and summary["swaps"] == [], err


def test_clock_pause_and_resume(launches, community):
    process = launches.start(ALPHA, "--set", f"name={community}", "--set", "pause_at_step=200", "--until", "20")
    wait_registered(community)
    assert subset(wait_paused(community), "step", "paused") == {"step": 200, "paused": True}
    assert process.poll() is None
    resumed = nearsub("clock", community, "resume")
    assert resumed.returncode == 0, resumed.stderr
    code, summary, err = finish(process)
    assert code == 0 and summary["steps"] == 400, err


def test_warp_changes_at_run_time_is_reported_and_keeps_the_trajectory(launches, community):
    process = launches.start(ALPHA, "--set", f"name={community}", "--set", "pause_at_step=200", "--until", "40")
    wait_registered(community)
    paused = wait_paused(community)
    assert paused["warp"] == 0.0 and paused["t"] == pytest.approx(10.0)
    assert nearsub("clock", community, "warp", "-1").returncode == 2
    warp = nearsub("clock", community, "warp", "5")
    assert warp.returncode == 0 and json.loads(warp.stdout)["warp"] == 5.0, warp.stderr
    resumed = time.monotonic()  # the clock resumes after this
    assert nearsub("clock", community, "resume").returncode == 0
    mission = load_mission(ALPHA, [f"name={community}", "time_limit=40"])
    deadline = time.monotonic() + mission.startup_timeout + mission.step_timeout
    achieved = []
    while time.monotonic() < deadline and process.poll() is None:
        status = nearsub("clock", community, "status")
        if status.returncode != 0:
            break  # the mission ended between two polls
        data = json.loads(status.stdout)
        assert data["warp"] == 5.0
        # Paced: never ahead of 100 steps per wall second since the resume (plus the grant window).
        assert data["step"] - 200 <= (time.monotonic() - resumed) * 5.0 / mission.dt + 20
        if data["achieved_warp"] is not None and data["step"] > 200:
            achieved.append(data["achieved_warp"])
            if achieved[-1] > 2.5:
                break
        time.sleep(0.2)
    assert achieved and achieved[-1] > 2.5, achieved
    code, summary, err = finish(process)
    assert code == 0 and summary["steps"] == 800, err
    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    logged = per_topic(log_path(summary))
    for leaf in ("state", "desired", "input"):
        assert logged[f"remus100/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf


def test_an_operator_steers_a_running_mission_and_the_log_replays_it(launches, community):
    process = launches.start(ALPHA, "--set", f"name={community}", "--set", "pause_at_step=100", "--until", "30")
    wait_registered(community)
    wait_paused(community)
    # Degrees as a person types them (psi_d_deg), radians on the wire: 0.5 rad.
    steer = nearsub("tap", "pub", community, "remus100/desired", f'{{"u_d": 1.0, "psi_d_deg": {math.degrees(0.5)!r}}}')
    assert steer.returncode == 0, steer.stderr
    assert "pid: operator desired from step 100: u_d=1.0, psi_d_deg=28.648" in steer.stdout
    state = nearsub("tap", "pub", community, "remus100/state", '{"u": 1, "v": 0, "r": 0, "x": 0, "y": 0, "psi": 0}')
    assert state.returncode == 2 and "state is accepted only from the app that computes it" in state.stderr
    assert nearsub("clock", community, "resume").returncode == 0
    code, summary, err = finish(process)
    assert code == 0 and summary["outcome"] == "time_limit", err

    records = read_log(log_path(summary)).records
    events = [r.value() for r in records if r.topic.endswith("/events/pid-1")]
    [override] = [e for e in events if e["detail"].startswith("operator")]
    assert override["step"] == 100 and override["data"]["leaf"] == "desired"
    replay = [("pid", "desired", override["step"], Desired(**override["data"]["message"]))]
    mission = load_mission(ALPHA, [f"name={community}", "time_limit=30"])
    cores, schedule = build_cores(mission), Schedule(mission.periods())
    reference = run_inprocess(cores, schedule, mission.dt, mission.max_steps, operator=replay)
    logged = per_topic(log_path(summary))
    for leaf in ("state", "input"):
        assert logged[f"remus100/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf
    unsteered = run_inprocess(build_cores(mission), schedule, mission.dt, mission.max_steps)
    assert logged["remus100/state"][:101] == [encode(m) for m in unsteered.topic("state")][:101]
    assert logged["remus100/state"][102] != encode(unsteered.topic("state")[102])  # it was steered


def test_a_forged_tick_far_ahead_is_refused_and_changes_nothing(launches, community):
    """A Tick granting a step the clock would never grant yet (`tap pub --no-validate`, fault
    injection) must not let the apps run ahead of the clock: the mission ends as it would have."""
    process = launches.start(ALPHA, "--set", f"name={community}", "--set", "pause_at_step=100", "--until", "20")
    wait_registered(community)
    assert wait_paused(community)["step"] == 100
    tick = json.dumps({"step": 10**6, "t": 0.0, "source": "clock"})
    forged = nearsub("tap", "pub", community, "clock/tick", tick, "--no-validate")
    assert forged.returncode == 0, forged.stderr
    assert nearsub("clock", community, "resume").returncode == 0
    code, summary, err = finish(process)
    assert code == 0 and summary["outcome"] == "time_limit" and summary["steps"] == 400, err
    mission = load_mission(ALPHA, [f"name={community}", "time_limit=20"])
    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    assert per_topic(log_path(summary))["remus100/state"] == [encode(m) for m in reference.topic("state")]
    errors = [r.value() for r in read_log(log_path(summary)).records if "/events/" in r.topic]
    assert any("tick to step 1000000 ignored" in e.get("detail", "") for e in errors)


def test_a_launch_on_a_terminal_prints_its_start_up_the_status_line_and_the_achieved_warp(tmp_path, community):
    """As pAntler and ros2 launch do: each app as it starts, the mission running, then (stdout a
    terminal) a status line each second with the achieved warp, and the summary's requested vs
    achieved warp."""
    mission = load_mission(ALPHA)
    until, warp = 8.0, 2.0  # 4 s of running: the status line, once a second, shows even on a busy machine
    primary, secondary = pty.openpty()
    argv = [sys.executable, "-m", "nearsub", "launch", str(ALPHA), "--set", f"name={community}"]
    argv += ["--warp", str(warp), "--until", str(until), "--log", str(tmp_path / "logs")]
    process = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=secondary, stderr=secondary, process_group=0)
    os.close(secondary)
    output = b""
    try:
        deadline = time.monotonic() + 2 * mission.startup_timeout + until / warp + mission.step_timeout
        while time.monotonic() < deadline:
            try:
                chunk = os.read(primary, 65536)
            except OSError:  # the terminal closes when the launcher and its apps have left it
                break
            if not chunk:
                break
            output += chunk
        process.wait(timeout=mission.step_timeout)
    finally:
        if process.poll() is None:
            process.kill()
        os.close(primary)
    text = output.decode(errors="replace")
    assert process.returncode == 0, text
    started = re.findall(r"\[launch +[\d.]+ s\] started (\S+) \(pid \d+\)", text)
    for app in ("router", "logger", "sim-1", "pid-1", "helm-1", "clock"):
        assert app in started, (app, started)
    assert re.search(rf"\[launch +[\d.]+ s\] mission {community} running: \d+ processes up", text), text
    assert re.search(r"\r\x1b\[Kt +[\d.]+ s +step +\d+ +warp [\d.]+ of 2 +u +[\d.-]+ m/s +at \(", text), text
    assert re.search(r"warp 2 requested, [\d.]+ achieved", text), text
