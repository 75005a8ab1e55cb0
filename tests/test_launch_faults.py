"""Bad input to `nearsub launch` and `nearsub log`: one line naming the culprit, exit 2 (bad input)
or 1 (a router that cannot be reached), no traceback, nothing left behind; and the pieces that
make a launch reliable: the router's ready file and the claim on a mission name."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time

import msgpack
import pytest

from conftest import ALPHA, nearsub
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.bus import free_tcp_port
from nearsub.common.runtime.logfile import LogWriter
from nearsub.tools.support import registry


def one_line(text: str) -> str:
    lines = text.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in text, text
    return lines[0]


def small_log(path, name: str, steps: int):
    writer = LogWriter(path)
    writer.metadata("mission", {"name": name})
    for i in range(steps):
        data = msgpack.packb({"step": i, "t": i * 0.05, "source": "pid", "X_prop": 1.0, "delta_r": 0.0})
        writer.write(f"nearsub/{name}/remus100/input", data, i * 0.05)
    writer.finish()
    return path


def test_log_info_on_a_missing_path_says_so_in_one_line(tmp_path):
    out = nearsub("log", "info", str(tmp_path / "nothing.mcap"))
    assert out.returncode == 2
    assert one_line(out.stderr) == f"nearsub log info: {tmp_path / 'nothing.mcap'}: no such file"


def test_log_info_on_a_file_that_is_not_mcap_exits_2(tmp_path):
    path = tmp_path / "notes.mcap"
    path.write_text("not a log\n")
    out = nearsub("log", "info", str(path))
    assert out.returncode == 2 and out.stdout == ""
    assert "not an MCAP log" in one_line(out.stderr)
    export = nearsub("log", "export", str(path))
    assert export.returncode == 2 and "not an MCAP log" in one_line(export.stderr)


def test_log_info_reads_every_log_a_glob_matches(tmp_path):
    small_log(tmp_path / "a.mcap", "a", 10)
    small_log(tmp_path / "b.mcap", "b", 30)
    for argv in ([str(tmp_path / "*.mcap")], [str(tmp_path / "a.mcap"), str(tmp_path / "b.mcap")]):
        out = nearsub("log", "info", *argv, "--json")
        assert out.returncode == 0, out.stderr
        infos = [json.loads(line) for line in out.stdout.splitlines()]
        assert [(i["file"].rsplit("/", 1)[-1], i["messages"]) for i in infos] == [("a.mcap", 10), ("b.mcap", 30)]
    missing = nearsub("log", "info", str(tmp_path / "a.mcap"), str(tmp_path / "c*.mcap"))
    assert missing.returncode == 2 and missing.stdout == "" and "no file matches" in one_line(missing.stderr)


def test_an_unreachable_router_fails_after_the_startup_timeout_naming_it(tmp_path, runtime_dir):
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"  # nothing listens there
    settings = [f'network.connect=["{endpoint}"]', "startup_timeout=2"]
    mission = load_mission(ALPHA, settings)
    started = time.monotonic()
    out = nearsub("launch", str(ALPHA), "--log", str(tmp_path / "logs"), *[a for s in settings for a in ("--set", s)])
    assert out.returncode == 1
    assert one_line(out.stderr) == (
        f"nearsub launch: cannot reach {endpoint} within {mission.startup_timeout:g} s "
        "(is the router running there, and does it require credentials?)"
    )
    assert time.monotonic() - started >= mission.startup_timeout  # it kept trying, then gave up
    assert not (tmp_path / "logs").exists() or list((tmp_path / "logs").iterdir()) == []  # no half-empty run folder


@pytest.mark.parametrize("endpoint", ["tcp/256.0.0.1:7447", "tcp/[::g]:7447", "tcp/localhost:99999"])
def test_a_malformed_network_connect_is_refused_at_once(tmp_path, runtime_dir, endpoint):
    out = nearsub("launch", str(ALPHA), "--log", str(tmp_path / "logs"), "--set", f'network.connect=["{endpoint}"]')
    assert out.returncode == 2
    line = one_line(out.stderr)
    assert "network.connect" in line and endpoint in line
    assert not (tmp_path / "logs").exists()


@pytest.mark.parametrize(
    ("argv", "problem"),
    [
        (["--vehicles", "auv9"], "--vehicles auv9: no vehicle named 'auv9' (auv1, auv2)"),
        (["--vehicles", "auv1,auv1"], "--vehicles auv1,auv1: auv1 is named twice"),
        (["--join"], "--join: name the vehicles whose apps run on this host with --vehicles"),
        (["--vehicles", "auv1", "--no-router"], "--vehicles auv1: the other vehicles' apps join from another host"),
    ],
)
def test_a_fleet_split_that_cannot_run_is_refused_naming_the_option(tmp_path, runtime_dir, argv, problem):
    """docs/network.md, "A fleet over several hosts": names of the mission's vehicles, each once,
    and a router the other hosts reach (network.connect)."""
    from test_fleet import TWO

    router = [] if "--no-router" in argv else ["--set", 'network.connect=["tcp/127.0.0.1:9"]']
    given = [a for a in argv if a != "--no-router"]
    out = nearsub("launch", str(TWO), "--log", str(tmp_path / "logs"), *router, *given)
    assert out.returncode == 2
    assert one_line(out.stderr).startswith(f"nearsub launch: {problem}")
    assert not (tmp_path / "logs").exists()


@pytest.mark.parametrize(
    ("content", "problem"),
    [(None, "no such file"), ("not a model", "not a nearsub model file (not an .npz archive)")],
)
def test_an_unusable_surrogate_model_is_refused_before_any_app_starts(tmp_path, runtime_dir, content, problem):
    model = tmp_path / "model.npz"
    if content is not None:
        model.write_text(content)
    mission = ALPHA.parent / "overtake_stern_nuv.toml"
    out = nearsub("launch", str(mission), "--log", str(tmp_path / "logs"), "--set", f'surrogate.model="{model}"')
    assert out.returncode == 2
    assert one_line(out.stderr) == f"nearsub launch: surrogate.model = {str(model)!r}: {problem}"
    assert not (tmp_path / "logs").exists()


def test_the_router_reports_the_endpoint_it_listens_on(tmp_path):
    ready = tmp_path / "router.json"
    router = subprocess.Popen(
        [sys.executable, "-m", "nearsub.apps.router", "--listen", "tcp/127.0.0.1:0", "--ready-file", str(ready)],
        stdout=subprocess.PIPE,
        text=True,
        process_group=0,
    )
    try:
        line = router.stdout.readline()  # printed once listening, after the ready file is written
        endpoints = json.loads(ready.read_text())
        assert line.strip() == f"router listening on {endpoints[0]}, admitting any session (no credentials)"
        host, port = endpoints[0].removeprefix("tcp/").rsplit(":", 1)
        assert host == "127.0.0.1" and int(port) > 0
        with socket.create_connection((host, int(port)), timeout=5):
            pass
    finally:
        router.send_signal(signal.SIGTERM)
        router.wait(timeout=30)


def test_a_name_is_claimed_by_one_process_until_it_releases_or_dies(runtime_dir):
    with registry.claim("alpha"):
        with pytest.raises(registry.NameTaken, match=r"'alpha' is already running \(launcher pid \d+\)"):
            registry.claim("alpha")
    registry.claim("alpha").release()  # released: free again
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from nearsub.tools.support import registry; c = registry.claim('alpha'); "
            "print('held', flush=True); time.sleep(600)",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(registry.NameTaken, match=f"pid {holder.pid}"):
            registry.claim("alpha")
    finally:
        holder.kill()
        holder.wait()
    registry.claim("alpha").release()  # the dead holder's claim went with it


class _ExitsWhileAsked:
    """A child process that is running at the first poll and has exited with `code` after it."""

    def __init__(self, code: int):
        self.code, self.polls, self.returncode = code, 0, None

    def poll(self):
        self.polls += 1
        if self.polls > 1:
            self.returncode = self.code
        return self.returncode


class _NoTokens:
    def alive(self, key, timeout=1.0):
        return []


@pytest.mark.parametrize("code", [0, 1])
def test_an_app_exiting_while_the_launcher_waits_for_it(tmp_path, code):
    """Exit code 0 between the token check and the exit check is an app that ended the mission
    (the sim refusing its settings at step 0): not a start-up failure. Another code is one."""
    from nearsub.tools.launcher.processes import Child, LaunchError, Processes

    processes = Processes(tmp_path, load_mission(ALPHA).startup_timeout, say=print)
    processes.children["sim-1"] = Child("sim-1", "sim", _ExitsWhileAsked(code), tmp_path / "sim-1.out")
    if code == 0:
        processes.wait_alive(_NoTokens(), "alpha", [("sim", "sim-1")], timeout=5.0)
    else:
        with pytest.raises(LaunchError, match="sim-1 exited with code 1 during start-up"):
            processes.wait_alive(_NoTokens(), "alpha", [("sim", "sim-1")], timeout=5.0)
