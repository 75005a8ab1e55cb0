"""`nearsub view` in a real browser: headless Chromium (Debian's package) loads the page of a live
mission and of a replayed log. The page exposes what it drew last (`window.nearsub.drawn`, and a
history of drawn states); the test compares it with the state topic (`nearsub tap echo`) and the
log, and pauses and resumes the mission from the page's buttons.

`tools/test.sh` installs Chromium where it is missing; the test skips only on a machine without
apt-get, where it could not be installed.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
import urllib.parse
import urllib.request
from pathlib import Path

import pytest
from browser import Browser, chromium_path
from websockets.sync.client import connect

from conftest import ALPHA
from helpers import finish, page_urls, socket_url, wait_registered
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.logfile import LogWriter, read_log
from nearsub.tools.commands.view import start_viewer

MISSION = load_mission(ALPHA)
# Every wait below is derived from the mission's own timeouts: start-up, and one step.
STARTUP = MISSION.startup_timeout
STEP = MISSION.step_timeout

pytestmark = pytest.mark.timeout(int(6 * STARTUP + 10 * STEP))


@pytest.fixture
def chromium():
    if chromium_path() is None:
        if shutil.which("apt-get") is None:
            pytest.skip("no chromium, and no apt-get to install Debian's chromium package on this machine")
        pytest.fail("chromium is missing: tools/test.sh installs it (apt-get install chromium chromium-driver)")
    with Browser(timeout=STARTUP) as browser:
        yield browser


class Viewer:
    """A `nearsub view TARGET` subprocess and the URL it prints."""

    def __init__(self, target: str, *args: str):
        self.process = subprocess.Popen(
            [sys.executable, "-m", "nearsub", "view", target, *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            process_group=0,
        )
        lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=lambda: [lines.put(line) for line in self.process.stdout], daemon=True).start()
        try:
            line = lines.get(timeout=STARTUP)
        except queue.Empty:
            self.stop()
            raise AssertionError(f"nearsub view printed no URL within {STARTUP:g} s") from None
        assert line.startswith("nearsub view: http://127.0.0.1:"), line
        self.url, self.read_only = page_urls(line)

    def stop(self) -> None:
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGTERM)
            self.process.wait(timeout=STEP)


@pytest.fixture
def viewers():
    started: list[Viewer] = []
    yield lambda target, *args: started.append(Viewer(target, *args)) or started[-1]
    for viewer in started:
        viewer.stop()


def nearsub_json(*args: str) -> dict:
    done = subprocess.run(
        [sys.executable, "-m", "nearsub", *args], capture_output=True, text=True, timeout=STARTUP + STEP
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def clock_status(community: str) -> dict:
    return nearsub_json("clock", community, "status")


def wait_clock(community: str, paused: bool) -> dict:
    deadline = time.monotonic() + STEP + STARTUP
    while time.monotonic() < deadline:
        status = clock_status(community)
        if status["paused"] == paused:
            return status
        time.sleep(0.2)
    raise AssertionError(f"the clock of {community} did not report paused={paused}")


def test_live_view_follows_the_state_topic_pauses_resumes_and_swaps_from_the_page(
    launches, community, chromium, viewers
):
    launch = launches.start(ALPHA, "--set", f"name={community}", "--warp", "1", "--until", "300")
    wait_registered(community, timeout=2 * STARTUP + STEP)  # every app up, each within STARTUP
    viewer = viewers(community)
    chromium.open(viewer.url)
    chromium.wait_for("window.nearsub.drawn !== null", timeout=STARTUP)
    # The state topic as `nearsub tap echo` prints it, while the page (loaded: it has drawn)
    # draws the same mission.
    key = f"nearsub/{community}/{MISSION.vehicle_name}/state"
    tap = subprocess.Popen(
        [sys.executable, "-m", "nearsub", "tap", "echo", community, key, "--count", "60", "--json"],
        stdout=subprocess.PIPE,
        text=True,
    )
    tapped_out, _ = tap.communicate(timeout=STARTUP + 60 * MISSION.dt)  # 60 states at warp 1
    tapped = {line["value"]["step"]: line["value"] for line in map(json.loads, tapped_out.splitlines())}
    drawn = {d["step"]: d for d in chromium.evaluate("window.nearsub.history")}
    common = sorted(set(tapped) & set(drawn))
    assert len(common) >= 5, f"page drew steps {sorted(drawn)[:5]}..., tap saw {sorted(tapped)[:5]}..."
    for step in common:
        assert (drawn[step]["x"], drawn[step]["y"], drawn[step]["psi"]) == (
            tapped[step]["x"],
            tapped[step]["y"],
            tapped[step]["psi"],
        ), f"step {step}"
    steps = [d["step"] for d in chromium.evaluate("window.nearsub.history")]
    assert steps == sorted(steps) and steps[-1] > steps[0]  # it follows the mission forwards

    chromium.evaluate("document.getElementById('pause').click()")
    paused = wait_clock(community, paused=True)
    chromium.wait_for("window.nearsub.frame.status.paused === true", timeout=STEP)
    chromium.wait_for(
        "document.getElementById('st-state').textContent === 'paused'", timeout=STEP
    )  # what a person sees
    held = chromium.evaluate("window.nearsub.drawn.step")
    time.sleep(1.0)
    assert chromium.evaluate("window.nearsub.drawn.step") == held  # nothing moves while paused
    assert clock_status(community)["step"] == paused["step"]
    replies = chromium.evaluate("window.nearsub.replies")
    assert any(r["cmd"] == "pause" and r["ok"] for r in replies)

    chromium.evaluate("document.getElementById('resume').click()")
    wait_clock(community, paused=False)
    chromium.wait_for(f"window.nearsub.drawn.step > {held}", timeout=STEP)

    # Swap the helm from the page (alpha has no submarine, so the standard behaviour is the one
    # that validates): the launcher's swap answers and its event reaches the page's list.
    chromium.evaluate("document.getElementById('behaviour').value = 'waypoints'")
    chromium.evaluate("document.getElementById('swap').click()")
    swap = chromium.wait_for("window.nearsub.replies.find(r => r.cmd === 'swap')", timeout=STARTUP + 2 * STEP)
    assert swap["ok"], swap
    chromium.wait_for("window.nearsub.frame.events.some(e => e.kind === 'swap')", timeout=STEP)

    launch.send_signal(signal.SIGINT)
    code, summary, _ = finish(launch, timeout=STARTUP + STEP)
    ended = "['pause', 'resume', 'warp-set', 'swap'].every((id) => document.getElementById(id).disabled)"
    chromium.wait_for(f"window.nearsub.frame.status.outcome !== null && {ended}", timeout=STEP)
    controls = [r for r in read_log(summary["log"]).records if r.topic == f"nearsub/{community}/control/clock"]
    commands = [r.value()["cmd"] for r in controls]
    assert "pause" in commands and "resume" in commands  # the page's actions are in the log
    assert summary["swaps"], summary


def test_replay_scrubs_to_a_time_and_draws_the_logged_state(launches, community, chromium, viewers, tmp_path):
    code, summary, err = launches.run(
        ALPHA, "--set", f"name={community}", "--warp", "0", "--until", "30", timeout=STARTUP + 30 * STEP
    )
    assert code == 0, err
    states = {r.value()["step"]: r.value() for r in read_log(summary["log"]).records if r.topic.endswith("/state")}
    viewer = viewers(summary["log"])
    chromium.open(viewer.url)
    chromium.wait_for("window.nearsub.drawn !== null", timeout=STARTUP)
    assert chromium.evaluate("document.getElementById('timeline').hidden") is False
    chromium.evaluate("const s = document.getElementById('scrub'); s.value = 12.5; s.oninput()")
    step = chromium.wait_for("window.nearsub.drawn.t === 12.5 && window.nearsub.drawn.step", timeout=STEP)
    drawn = chromium.evaluate("window.nearsub.drawn")
    logged = states[step]
    assert (drawn["x"], drawn["y"], drawn["psi"]) == (logged["x"], logged["y"], logged["psi"])
    chromium.evaluate("document.getElementById('play').click()")
    chromium.wait_for("window.nearsub.drawn.t > 12.5", timeout=STEP)


def test_view_rejects_bad_targets_and_options_with_one_line(runtime_dir, tmp_path):
    (tmp_path / "text.mcap").write_text("not a log\n")
    LogWriter(tmp_path / "empty.mcap").finish()
    cases = [
        ([str(tmp_path / "empty.mcap")], "has no state messages"),
        ([str(tmp_path / "gone.mcap")], "no such file"),
        ([str(tmp_path / "text.mcap")], "not an MCAP log"),
        (["nosuchmission"], "no running mission named"),
        (["alpha", "--run", str(tmp_path / "run.json")], "not a readable run file"),
    ]
    for args, words in cases:
        done = subprocess.run(
            [sys.executable, "-m", "nearsub", "view", *args], capture_output=True, text=True, timeout=STARTUP
        )
        assert done.returncode == 2, args
        assert len(done.stderr.strip().splitlines()) == 1 and words in done.stderr, done.stderr
    done = subprocess.run(  # argparse: its usage, then the option and value
        [sys.executable, "-m", "nearsub", "view", "alpha", "--port", "70000"],
        capture_output=True,
        text=True,
        timeout=STARTUP,
    )
    assert done.returncode == 2 and "argument --port: wants a whole number >= 0 and <= 65535" in done.stderr


def test_start_viewer_serves_the_mission_of_a_launcher_run_file(launches, community):
    """How `nearsub launch --view` starts the viewer: from the run file, before any registry lookup."""
    launches.start(ALPHA, "--set", f"name={community}", "--warp", "1", "--until", "300")
    entry = wait_registered(community, timeout=2 * STARTUP + STEP)
    process, urls = start_viewer(Path(entry["log"]).parent / "run.json", timeout=STARTUP)
    url = page_urls(urls)[0]
    try:
        with urllib.request.urlopen(url, timeout=STEP) as page:
            assert b"viewer.js" in page.read()
        with connect(socket_url(url), open_timeout=STEP) as socket:
            scene = json.loads(socket.recv(timeout=STEP))
            assert scene["type"] == "scene" and scene["community"] == community
            assert [leg["name"] for leg in scene["legs"]] == ["survey", "return"]  # the mission's legs
            deadline = time.monotonic() + STARTUP
            while (frame := json.loads(socket.recv(timeout=STEP)))["vehicle"] is None:
                assert time.monotonic() < deadline, "no state reached the viewer"
            assert frame["type"] == "frame" and frame["vehicle"]["step"] >= 0
    finally:
        os.killpg(process.pid, signal.SIGTERM)
        process.wait(timeout=STEP)


def seek(chromium, t: float) -> None:
    """Move the replay's timeline to t (a block: each evaluation shares the page's global scope)."""
    chromium.evaluate(f"{{ const s = document.getElementById('scrub'); s.value = {t}; s.oninput(); }}")


def readout(chromium) -> list[str]:
    """The page's readout of the selected vehicle: its name, x and y as shown."""
    return chromium.evaluate("['readout-of', 'r-x', 'r-y'].map((id) => document.getElementById(id).textContent)")


def test_replay_of_two_vehicles_draws_both_and_selects_either(chromium, viewers, tmp_path):
    from logsample import write_fleet_log

    path = tmp_path / "fleet.mcap"
    write_fleet_log(path)
    states = {}
    for r in read_log(path).records:
        if r.topic.endswith("/state"):
            states[(r.topic.split("/")[2], r.value()["step"])] = r.value()
    viewer = viewers(str(path))
    chromium.open(viewer.url)
    chromium.wait_for("window.nearsub.drawn !== null", timeout=STARTUP)
    assert chromium.evaluate("document.getElementById('vehicle-row').hidden") is False
    assert chromium.evaluate("[...document.getElementById('vehicle').options].map(o => o.value)") == ["alfa", "bravo"]
    seek(chromium, 4)
    chromium.wait_for("window.nearsub.drawnAll.alfa.t === 4 && window.nearsub.drawnAll.bravo.t === 4", timeout=STEP)
    drawn = chromium.evaluate("window.nearsub.drawnAll")
    for name in ("alfa", "bravo"):
        logged = states[(name, drawn[name]["step"])]
        assert (drawn[name]["x"], drawn[name]["y"], drawn[name]["psi"]) == (logged["x"], logged["y"], logged["psi"])
    assert chromium.evaluate("window.nearsub.drawn.y") == drawn["alfa"]["y"]  # the first is selected
    assert readout(chromium) == ["alfa", f"{drawn['alfa']['x']:.2f}", f"{drawn['alfa']['y']:.2f}"]
    chromium.evaluate("{ const v = document.getElementById('vehicle'); v.value = 'bravo'; v.onchange(); }")
    assert chromium.evaluate("window.nearsub.drawn.y") == drawn["bravo"]["y"]
    assert readout(chromium) == ["bravo", f"{drawn['bravo']['x']:.2f}", f"{drawn['bravo']['y']:.2f}"]
    labels = chromium.evaluate("window.nearsub.labels")  # each drawn with its name
    assert sorted(labels) == ["alfa", "bravo"] and all(labels[n].startswith(n) for n in labels)
    grid = chromium.evaluate("window.nearsub.gridLabels")  # each grid line says its coordinate
    assert grid["x"] and grid["y"] and all(float(v) % grid["step"] == 0 for v in grid["x"] + grid["y"])
    # bravo's log ends at 5 s: past it, bravo stays at its last state while alfa moves on.
    seek(chromium, 8)
    chromium.wait_for("window.nearsub.drawnAll.alfa.t === 8", timeout=STEP)
    assert chromium.evaluate("window.nearsub.drawnAll.bravo.t") == 5
    # A replay opened at a time (?t=), with its whole duration beside the cursor.
    page = urllib.parse.urlsplit(viewer.url)
    chromium.open(page._replace(query=urllib.parse.urlencode([*urllib.parse.parse_qsl(page.query), ("t", 6)])).geturl())
    chromium.wait_for("window.nearsub.drawnAll.alfa && window.nearsub.drawnAll.alfa.t === 6", timeout=STARTUP)
    chromium.wait_for("document.getElementById('cursor').textContent === '6.00 / 10.00 s'", timeout=STEP)


def test_live_view_follows_every_vehicle_of_a_running_mission(runtime_dir, community, viewers, monkeypatch, tmp_path):
    """Live, through the bus alone (--connect: no log to read first): a replay of the two-vehicle
    log at warp 1 stands for a running mission of two vehicles."""
    from logsample import write_fleet_log
    from test_log_play import start_player
    from test_log_play import wait_registered as wait_replay

    from nearsub.common.runtime.processes import stop

    path = tmp_path / "fleet.mcap"
    write_fleet_log(path, seconds=60.0)
    player = start_player(path, "--warp", 1, "--name", community, "--wait", STARTUP)
    try:
        entry = wait_replay(community, player)
        monkeypatch.setenv("NEARSUB_CREDENTIALS", entry["credentials"])
        viewer = viewers(community, "--connect", entry["connect"][0])
        with connect(socket_url(viewer.url), open_timeout=STEP) as socket:
            assert json.loads(socket.recv(timeout=STEP))["type"] == "scene"
            deadline = time.monotonic() + STARTUP
            while True:
                frame = json.loads(socket.recv(timeout=STEP))
                drawn = {v["name"]: v["vehicle"] for v in frame["vehicles"] if v["vehicle"] is not None}
                if len(drawn) == 2 and any(e["vehicle"] == "bravo" for e in frame["events"]):
                    break
                assert time.monotonic() < deadline, f"the viewer drew {sorted(drawn)} only"
    finally:
        stop([player])
    assert sorted(drawn) == ["alfa", "bravo"]
    assert drawn["bravo"]["y"] - drawn["alfa"]["y"] == pytest.approx(30.0, abs=2.0)  # 30 m apart, near in time
