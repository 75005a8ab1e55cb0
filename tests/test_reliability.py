"""Reliability under load and faults: missions start on a busy machine, every process the launcher
started is watched, and a mission name is held by one launcher at a time.

Every test here runs with two CPU-burning processes beside it (`busy_machine`), as when a user
runs a sweep next to a mission on a two-core machine. No test sleeps for a fixed time: each
waits for what it needs, bounded by a budget derived from the mission's own startup_timeout and
step_timeout. Run them with `pytest -m reliability -s` (the figures are printed); the default
run leaves them out.

The 200,000-step soak is in test_soak.py (`pytest -m soak -s`).
"""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time

import pytest

from conftest import ROOT
from helpers import (
    clock_status,
    finish,
    log_path,
    page_urls,
    per_topic,
    process_with,
    processes_under,
    socket_url,
    wait_paused,
    wait_registered,
)
from nearsub.common.mission.cores import build_cores
from nearsub.common.mission.schema import Mission, load_mission
from nearsub.common.runtime import forkserver
from nearsub.common.runtime.lifecycle import Schedule, run_inprocess
from nearsub.common.runtime.logfile import read_log
from nearsub.common.runtime.messages import encode

pytestmark = [pytest.mark.reliability, pytest.mark.timeout(600)]

ALPHA = ROOT / "missions" / "alpha.toml"
NEAR_SUBMARINE = ROOT / "missions" / "lateral_approach.toml"  # needs the surrogate server
START_GROUPS = (
    5  # sequential waits of a launch, each bounded by startup_timeout: router, logger, surrogate, apps, clock
)


@pytest.fixture
def busy_machine():
    """Two processes that burn a core each for the length of the test."""
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    yield
    for burner in burners:
        burner.kill()
        burner.wait()


def start_budget(mission: Mission) -> float:
    """Wall seconds a launch may take to have every app up: each start-up wait is bounded."""
    return START_GROUPS * mission.startup_timeout


def run_budget(mission: Mission) -> float:
    """Wall seconds a whole mission may take: start-up, the simulated time at its warp (as fast
    as possible counts as real time here), one stalled step, and stopping (the stop ladder)."""
    warp = mission.warp if mission.warp > 0 else 1.0
    return start_budget(mission) + mission.time_limit / warp + mission.step_timeout + 15.0


class Lines:
    """Lines of a stream as they come, each with the monotonic time it was read."""

    def __init__(self, stream):
        self._queue: queue.Queue = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._pump, args=(stream,), daemon=True).start()

    def _pump(self, stream) -> None:
        for line in stream:
            self._queue.put((time.monotonic(), line))
        self._queue.put((time.monotonic(), None))

    def wait_for(self, text: str, timeout: float) -> float:
        """The time the first line containing `text` was read; fails after `timeout`."""
        end = time.monotonic() + timeout
        while (left := end - time.monotonic()) > 0:
            try:
                at, line = self._queue.get(timeout=left)
            except queue.Empty:
                break
            if line is None:
                break
            self.seen.append(line)
            if text in line:
                return at
        raise AssertionError(f"no line with {text!r} within {timeout:g} s; got {self.seen}")

    def rest(self) -> str:
        while True:
            try:
                _, line = self._queue.get(timeout=5.0)
            except queue.Empty:
                break
            if line is None:
                break
            self.seen.append(line)
        return "".join(self.seen)


def test_three_missions_start_at_once_on_a_loaded_machine(busy_machine, launches):
    overrides = ["--until", "20"]
    mission = load_mission(ALPHA, ["time_limit=20"])
    names = [f"load{i}_{os.getpid()}" for i in range(3)]
    started = time.monotonic()
    processes = [launches.start(ALPHA, "--set", f"name={name}", *overrides) for name in names]
    summaries = []
    for process in processes:
        out, err = process.communicate(timeout=run_budget(mission))
        assert process.returncode == 0, err
        summaries.append(json.loads(out.strip().splitlines()[-1]))
    print(f"\n3 concurrent launches beside 2 busy loops: all done in {time.monotonic() - started:.1f} s")
    for name, summary in zip(names, summaries, strict=True):
        assert summary["community"] == name and summary["outcome"] == "time_limit"
        assert summary["steps"] == mission.max_steps
        contents = read_log(summary["log"])
        assert not contents.recovered and contents.metadata["outcome"]["outcome"] == "time_limit"


# (instance, the marker that finds its process): the services the launcher starts and one of each
# lock-stepped kind that test_faults does not kill.
KILLED = {
    "logger": "logger",
    "router": "nearsub.apps.router",
    "surrogate": "surrogate",
    "clock": "clock",
}


@pytest.mark.parametrize("instance", list(KILLED))
def test_a_killed_process_is_named_within_half_a_step_timeout(busy_machine, launches, community, instance):
    settings = [f"name={community}", "step_timeout=4", "warp=2"]
    mission = load_mission(NEAR_SUBMARINE, settings)
    args = [a for s in settings for a in ("--set", s)]
    process = launches.start(NEAR_SUBMARINE, *args)
    wait_registered(community, timeout=start_budget(mission))
    stderr = Lines(process.stderr)
    os.kill(process_with(launches.log_dir, KILLED[instance]), signal.SIGKILL)
    killed = time.monotonic()
    # A dead process must be named sooner than the clock would name a stalled one.
    limit = mission.step_timeout / 2
    reported = stderr.wait_for(f"app {instance} exited with code -9", timeout=run_budget(mission))
    out, _ = process.communicate(timeout=run_budget(mission))
    err = stderr.rest()
    print(
        f"\nkilled {instance}: reported after {reported - killed:.2f} s, launcher exited after "
        f"{time.monotonic() - killed:.2f} s"
    )
    assert reported - killed < limit, err
    summary = json.loads(out.strip().splitlines()[-1])
    assert process.returncode == 1
    assert summary["outcome"] == "error" and summary["failed_app"] == instance, summary
    assert f"app {instance} exited" in summary["reason"]


def test_two_launches_of_one_name_race_and_one_refuses(busy_machine, launches, community):
    mission = load_mission(ALPHA, [f"name={community}", "time_limit=20"])
    first = launches.start(ALPHA, "--set", f"name={community}", "--until", "20")
    second = launches.start(ALPHA, "--set", f"name={community}", "--until", "20")
    results = {}
    for process in (first, second):
        out, err = process.communicate(timeout=run_budget(mission))
        results[process] = (process.returncode, out, err)
    codes = sorted(code for code, _, _ in results.values())
    assert codes == [0, 2], results
    refused = next(r for r in results.values() if r[0] == 2)
    winner = next(r for r in results.values() if r[0] == 0)
    lines = refused[2].strip().splitlines()
    assert len(lines) == 1 and f"a mission named {community!r} is already running" in lines[0], refused
    summary = json.loads(winner[1].strip().splitlines()[-1])
    assert summary["outcome"] == "time_limit" and summary["steps"] == mission.max_steps
    # The refused launch left nothing behind: one run folder, the winner's.
    assert [p.name for p in launches.log_dir.iterdir()] == [os.path.basename(os.path.dirname(summary["log"]))]


def test_a_name_in_use_on_a_shared_router_is_refused(busy_machine, launches, community, tmp_path):
    """Missions from two hosts on one router: the second launcher sees the first on the bus
    (its registry, on its own host, knows nothing of it)."""
    ready = tmp_path / "router.json"
    router = subprocess.Popen(
        [sys.executable, "-m", "nearsub.apps.router", "--listen", "tcp/127.0.0.1:0", "--ready-file", str(ready)],
        process_group=0,
    )
    try:
        settings = [f"name={community}", "time_limit=20", "warp=2"]
        mission = load_mission(ALPHA, settings)
        end = time.monotonic() + mission.startup_timeout
        while not ready.exists() and time.monotonic() < end:
            time.sleep(0.05)
        connect = f"network.connect={json.dumps(json.loads(ready.read_text()))}"
        args = [a for s in [*settings, connect] for a in ("--set", s)]
        first = launches.start(ALPHA, *args)
        wait_registered(community, timeout=start_budget(mission))
        other_host = dict(os.environ, NEARSUB_RUNTIME_DIR=str(tmp_path / "other-host"))
        second = subprocess.run(
            [sys.executable, "-m", "nearsub", "launch", str(ALPHA), "--log", str(tmp_path / "other"), *args],
            capture_output=True,
            text=True,
            env=other_host,
            timeout=start_budget(mission),
        )
        assert second.returncode == 2, second.stderr
        lines = second.stderr.strip().splitlines()
        assert len(lines) == 1 and "already running or starting on tcp/127.0.0.1:" in lines[0], lines
        out, err = first.communicate(timeout=run_budget(mission))
        assert first.returncode == 0, err  # the refused launcher did not disturb the running mission
        assert json.loads(out.strip().splitlines()[-1])["outcome"] == "time_limit"
    finally:
        os.killpg(router.pid, signal.SIGKILL)
        router.wait()


def assert_equals_inprocess(mission: Mission, summary: dict) -> None:
    """The logged trajectory is the in-process run's, bit for bit."""
    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    logged = per_topic(log_path(summary))
    for leaf in ("state", "desired", "input"):
        assert logged[f"remus100/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf


def settings_args(settings: list[str]) -> list[str]:
    return [a for s in settings for a in ("--set", s)]


PAUSE = 30.0  # wall seconds, three default step_timeouts


def test_a_30_s_pause_and_resume_completes_as_in_process(busy_machine, launches, community):
    settings = [f"name={community}", "pause_at_step=200", "time_limit=20"]
    mission = load_mission(ALPHA, settings)
    assert PAUSE > mission.step_timeout  # a stall timer that counted the pause would end it
    process = launches.start(ALPHA, *settings_args(settings))
    wait_registered(community, timeout=start_budget(mission))
    status = wait_paused(community, timeout=run_budget(mission))
    assert status["step"] == 200
    paused_at = time.monotonic()
    while (left := paused_at + PAUSE - time.monotonic()) > 0:
        assert process.poll() is None, "the mission ended during the pause"
        time.sleep(min(left, 1.0))
    assert clock_status(community)["paused"] and clock_status(community)["step"] == 200
    resumed = subprocess.run(
        [sys.executable, "-m", "nearsub", "clock", community, "resume"], capture_output=True, text=True, timeout=60
    )
    assert resumed.returncode == 0, resumed.stderr
    code, summary, err = finish(process, timeout=run_budget(mission))
    print(f"\npaused {time.monotonic() - paused_at:.1f} s in all; mission {summary['outcome']} at {summary['steps']}")
    assert code == 0 and summary["outcome"] == "time_limit" and summary["steps"] == mission.max_steps, err
    assert_equals_inprocess(mission, summary)


def test_a_swap_longer_than_step_timeout_keeps_the_mission_and_its_trajectory(
    busy_machine, launches, community, monkeypatch
):
    """The new helm's start-up takes longer than a 0.5 s step_timeout; the clock is paused
    meanwhile, so nothing stalls. The launcher starts it as a process of its own, not from the
    fork server, so it imports numpy and Zenoh itself (0.6 s of imports alone on an idle machine;
    forked, a swap took 0.41 s beside two busy loops and the test tested nothing; at a 2 s
    step_timeout, a fast machine swapped in 1.3 s)."""
    monkeypatch.setenv(forkserver.VARIABLE, "0")
    settings = [f"name={community}", "pause_at_step=300", "time_limit=30", "step_timeout=0.5"]
    mission = load_mission(ALPHA, settings)
    process = launches.start(ALPHA, *settings_args(settings))
    wait_registered(community, timeout=start_budget(mission))
    wait_paused(community, timeout=run_budget(mission))
    started = time.monotonic()
    argv = ["swap", community, "helm", "--at-step", "300", "--with", "behaviour=waypoints"]
    swap = subprocess.run(
        [sys.executable, "-m", "nearsub", *argv, "--timeout", f"{start_budget(mission) + 30:g}"],
        capture_output=True,
        text=True,
        timeout=start_budget(mission) + 60,
    )
    took = time.monotonic() - started  # the launcher resumes the clock when the swap is done
    assert swap.returncode == 0, swap.stderr
    code, summary, err = finish(process, timeout=run_budget(mission))
    print(f"\nswap took {took:.2f} s against a step_timeout of {mission.step_timeout:g} s")
    assert took > mission.step_timeout, f"the swap took {took:.2f} s: it did not test a swap longer than step_timeout"
    assert code == 0 and summary["outcome"] == "time_limit" and summary["steps"] == mission.max_steps, err
    assert summary["swaps"] == [{"old": "helm-1", "new": "helm-2", "step": 300}]
    assert_equals_inprocess(mission, summary)


def test_the_viewer_admits_its_tokens_only_and_only_the_control_token_controls(busy_machine, launches, community):
    import urllib.error
    import urllib.request

    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    mission = load_mission(ALPHA, [f"name={community}"])
    process = launches.start(ALPHA, "--set", f"name={community}", "--warp", "1", "--until", "300", "--view")
    stderr = Lines(process.stderr)
    stderr.wait_for("view at", timeout=start_budget(mission) + mission.startup_timeout)
    control, read_only = page_urls(next(line for line in stderr.seen if "view at" in line))
    port_url = control.split("?", 1)[0]
    step = mission.step_timeout
    for page in (port_url, port_url + "?token=wrong"):  # no token, a wrong one: 403, page and socket
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(page, timeout=step)
        assert refused.value.code == 403
        with pytest.raises(InvalidStatus) as refused:
            connect(socket_url(page), open_timeout=step)
        assert refused.value.response.status_code == 403
    with pytest.raises(InvalidStatus) as refused:  # the right token from another site's page
        connect(socket_url(control), origin="http://evil.example.com", open_timeout=step)
    assert refused.value.response.status_code == 403
    with urllib.request.urlopen(read_only, timeout=step) as page:
        assert b"viewer.js" in page.read()
    with connect(socket_url(read_only), open_timeout=step) as socket:
        scene = json.loads(socket.recv(timeout=step))
        assert scene["type"] == "scene" and scene["control"] is False
        assert json.loads(socket.recv(timeout=step))["type"] == "frame"
        for request in ({"cmd": "pause"}, {"cmd": "warp", "warp": 1e6}, {"cmd": "swap", "behaviour": "survey"}):
            socket.send(json.dumps(request))
            while (reply := json.loads(socket.recv(timeout=step)))["type"] != "reply":
                pass
            assert reply["ok"] is False and "read-only" in reply["text"], reply
    assert clock_status(community)["paused"] is False
    own_origin = port_url.rstrip("/")
    with connect(socket_url(control), origin=own_origin, open_timeout=step) as socket:
        assert json.loads(socket.recv(timeout=step))["control"] is True
        socket.send(json.dumps({"cmd": "pause"}))
        while (reply := json.loads(socket.recv(timeout=2 * step)))["type"] != "reply":
            pass
        assert reply["ok"] is True, reply
    wait_paused(community, timeout=mission.startup_timeout + step)
    # `nearsub view NAME` of the mission's owner derives the same tokens from the runtime folder.
    viewer = subprocess.Popen(
        [sys.executable, "-m", "nearsub", "view", community], stdout=subprocess.PIPE, text=True, process_group=0
    )
    try:
        line = Lines(viewer.stdout)
        line.wait_for("nearsub view:", timeout=mission.startup_timeout)
        assert control.split("?", 1)[1] in line.seen[-1] and read_only.split("?", 1)[1] in line.seen[-1]
    finally:
        os.killpg(viewer.pid, signal.SIGTERM)
        viewer.wait(timeout=step)


def free_port() -> int:
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def listening(url: str) -> bool:
    import socket

    host, port = url.split("//")[1].split("/")[0].split("?")[0].split(":")
    try:
        socket.create_connection((host, int(port)), timeout=1.0).close()
    except OSError:
        return False
    return True


def test_a_killed_launcher_leaves_nothing_running_and_the_next_launch_cleans_up(
    busy_machine, launches, community, runtime_dir
):
    """SIGKILL gives the launcher no chance to stop anything: every process it started must end by
    itself (parent-death signal), and the next launch removes the files it left."""
    from test_foxglove import companion_urls

    mission = load_mission(ALPHA, [f"name={community}"])
    port = free_port()  # the same fixed Foxglove port for both launches: the second needs it free
    args = ["--warp", "1", "--until", "300", "--view", "--foxglove", "--foxglove-port", str(port)]
    process = launches.start(ALPHA, "--set", f"name={community}", *args)
    urls = companion_urls(process, 2, timeout=start_budget(mission) + mission.startup_timeout)
    assert all(listening(url) for url in urls.values())
    assert (runtime_dir / f"{community}.credentials").exists()
    process.kill()
    killed = time.monotonic()
    budget = mission.startup_timeout + mission.step_timeout
    while processes_under(launches.log_dir) or any(listening(url) for url in urls.values()):
        left = {pid: " ".join(argv[:4]) for pid, argv in processes_under(launches.log_dir).items()}
        assert time.monotonic() - killed < budget, f"still running {budget:g} s after the launcher died: {left}"
        time.sleep(0.1)
    print(f"\nlauncher killed: every process it started gone after {time.monotonic() - killed:.2f} s")
    second = launches.start(
        ALPHA, "--set", f"name={community}-2", "--until", "5", "--foxglove", "--foxglove-port", str(port)
    )
    assert companion_urls(second, 1, timeout=start_budget(mission) + mission.startup_timeout)["foxglove"].endswith(
        f":{port}"
    )
    assert not (runtime_dir / f"{community}.credentials").exists()  # the dead launcher's, swept
    assert not (runtime_dir / f"{community}.json").exists()
    out, err = second.communicate(timeout=run_budget(mission))
    assert second.returncode == 0, err


@pytest.fixture
def small_disk(tmp_path):
    """A 1 MiB tmpfs (root only: mount(2) needs CAP_SYS_ADMIN), unmounted after the test."""
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root; the full-disk case runs as root only")
    folder = tmp_path / "small"
    folder.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(folder)], capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode().strip()}")
    yield folder
    subprocess.run(["umount", "-l", str(folder)], check=False)


def test_a_full_disk_is_named_in_the_summary_and_refused_at_start(busy_machine, launches, community, small_disk):
    """1 MiB holds the first minute of missions/alpha.toml but not its 900 s: the mission starts,
    fills the disk, and its summary says so; what was logged stays readable. A second launch on the
    full disk is refused before anything starts."""
    mission = load_mission(ALPHA, [f"name={community}"])
    launches.log_dir = small_disk
    code, summary, err = launches.run(ALPHA, "--set", f"name={community}", timeout=run_budget(mission))
    assert code == 1 and summary["outcome"] == "error", (summary, err)
    assert f"no space left on {small_disk}" in summary["reason"], summary["reason"]
    contents = read_log(summary["log"])
    print(f"\nfull disk: {summary['reason']!r}; {len(contents.records)} messages kept, to step {summary['steps']}")
    assert len(contents.records) > 1000 and contents.records[-1].sim_time > 30.0  # more than the first half-minute
    code, summary, err = launches.run(ALPHA, "--set", f"name={community}-2", timeout=start_budget(mission))
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert f"--log {small_disk}: no space left on it" in err
