"""The fork server (common/runtime/forkserver.py): modules forked from a pre-imported parent keep
`processes.spawn_app`'s contract (own process group, one BLAS thread, the requester's environment,
output into the given file, exit codes as subprocess gives them), report their CPU at exit, and
leave nothing behind."""

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

from conftest import ALPHA, nearsub
from helpers import command_line, finish, process_with, wait_registered
from nearsub.common.runtime import forkserver, processes
from nearsub.common.runtime.forkserver import ForkedApp, ForkServer, ForkServerError, process_cpu

pytestmark = pytest.mark.timeout(120)
WAIT = 60.0  # wall seconds for a forked module to start or end on a busy machine

# A module that writes what a launched app would check about itself, then sleeps ("wait") or
# exits with the code in its first argument.
PROBE = """
import json, os, sys, time
from nearsub.common.runtime.processes import prepare_process
prepare_process()  # as every app does: SIGTERM when its parent dies
print(json.dumps({"argv": sys.argv[1:], "env": dict(os.environ), "group": os.getpgid(0), "pid": os.getpid(),
                  "stdin": sys.stdin.read()}), flush=True)
print("to stderr", file=sys.stderr, flush=True)
if sys.argv[1] == "wait":
    time.sleep(300)
raise SystemExit(int(sys.argv[1]))
"""


@pytest.fixture
def server(tmp_path, monkeypatch):
    (tmp_path / "forkprobe.py").write_text(PROBE)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")])))
    started = ForkServer(("json",))
    yield started
    started.close()
    try:
        started.process.wait(timeout=WAIT)
    except subprocess.TimeoutExpired:
        started.process.kill()


def probe(server: ForkServer, path, *args: str) -> ForkedApp:
    with open(path, "wb") as handle:
        return server.spawn("forkprobe", list(args), handle, WAIT)


def said(path) -> dict:
    deadline = time.monotonic() + WAIT
    while not path.read_text().strip():
        assert time.monotonic() < deadline, "the forked module wrote nothing"
        time.sleep(0.02)
    return json.loads(path.read_text().splitlines()[0])


def test_a_forked_module_gets_its_arguments_the_environment_a_group_and_its_exit_code(server, tmp_path, monkeypatch):
    for name in processes.BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("NEARSUB_LINK", "client")  # set after the server started: the request carries it
    out = tmp_path / "probe.out"
    app = probe(server, out, "3", "--instance", "sim-1")
    assert app.wait(WAIT) == 3
    seen = said(out)
    assert seen["argv"] == ["3", "--instance", "sim-1"]
    assert seen["env"]["NEARSUB_LINK"] == "client"
    assert {name: seen["env"].get(name) for name in processes.BLAS_THREAD_VARIABLES} == dict.fromkeys(
        processes.BLAS_THREAD_VARIABLES, "1"
    )
    assert seen["group"] == seen["pid"] == app.pid  # a process group of its own, as spawn_app gives
    assert seen["stdin"] == ""  # /dev/null
    assert out.read_text().splitlines()[1] == "to stderr"  # stderr into the same file
    assert "OPENBLAS_NUM_THREADS" not in os.environ  # the requester's own environment is left alone
    assert app.cpu is not None and app.cpu > 0.0
    assert process_cpu(app) == app.cpu  # reaped by the server: the figure it reported


def test_a_preloaded_app_module_runs_without_runpy_warnings(tmp_path, monkeypatch):
    """The launcher preloads the apps' modules (`nearsub.apps.sim`, ...); running one again as
    __main__ must not print runpy's warning into the app's output, which a failed start-up shows."""
    package = tmp_path / "forkpkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "app.py").write_text('if __name__ == "__main__":\n    print("ran", flush=True)\n')
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")])))
    started = ForkServer(("forkpkg.app",))
    try:
        out = tmp_path / "app.out"
        with open(out, "wb") as handle:
            app = started.spawn("forkpkg.app", [], handle, WAIT)
        assert app.wait(WAIT) == 0
        assert out.read_text() == "ran\n"
    finally:
        started.close()


def test_an_exit_reported_with_the_pid_is_kept(server, tmp_path):
    """A module that exits at once: the server's exit report can come in the same read as its pid
    (a fresh clone once lost it and waited forever)."""
    apps = [probe(server, tmp_path / f"probe{k}.out", str(k % 5)) for k in range(20)]
    assert [app.wait(WAIT) for app in apps] == [k % 5 for k in range(20)]


def test_an_exit_in_the_same_read_as_its_pid_is_kept(tmp_path):
    """The client side alone, against a socket that answers a spawn with the pid and the exit
    together (what a server that was descheduled between its fork and its reply sends)."""
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    client = ForkServer.__new__(ForkServer)
    client._attach(ours, process=None)
    theirs.sendall(b'{"pid": 4242}\n{"exited": 4242, "code": 3, "cpu": 0.25}\n')
    with open(tmp_path / "out", "wb") as handle:
        app = client.spawn("forkprobe", ["3"], handle, WAIT)
    assert (app.returncode, app.cpu) == (3, 0.25)
    theirs.close()
    ours.close()


def test_the_cpu_of_an_app_reaped_before_its_report_came_is_the_reported_one(tmp_path):
    """The server reaps an app (its /proc entry goes) a moment before its report reaches the
    launcher; the launcher's CPU figures at the mission end fell in between and lost that app."""
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    client = ForkServer.__new__(ForkServer)
    client._attach(ours, process=None)
    gone = subprocess.Popen(["true"])
    gone.wait()  # reaped: a pid with no /proc entry, as a reaped app's
    theirs.sendall(json.dumps({"pid": gone.pid}).encode() + b"\n")
    with open(tmp_path / "out", "wb") as handle:
        app = client.spawn("forkprobe", [], handle, WAIT)
    report = json.dumps({"exited": gone.pid, "code": 0, "cpu": 0.25}).encode() + b"\n"
    threading.Timer(0.2 * forkserver.EXIT_REPORT_WAIT, theirs.sendall, [report]).start()
    assert process_cpu(app) == 0.25
    theirs.close()
    ours.close()


def test_a_server_that_does_not_answer_in_time_is_killed(tmp_path):
    """It must never fork the app late, beside the one the launcher then starts itself."""
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    silent = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    client = ForkServer.__new__(ForkServer)
    client._attach(ours, silent)
    with (
        pytest.raises(ForkServerError, match="did not fork forkprobe within 0.2 s"),
        open(tmp_path / "o", "wb") as handle,
    ):
        client.spawn("forkprobe", ["0"], handle, 0.2)
    assert silent.wait(timeout=WAIT) == -signal.SIGKILL
    theirs.close()
    ours.close()


def test_a_forked_module_reads_as_its_command_line_in_ps(server, tmp_path):
    out = tmp_path / "probe.out"
    app = probe(server, out, "wait", "--run", "logs/x/run.json")
    try:
        said(out)
        words = command_line(app.pid)
        cpu = process_cpu(app)
    finally:
        processes.stop([app], wait=5.0)
    assert words == [sys.executable, "-u", "-m", "forkprobe", "wait", "--run", "logs/x/run.json"]
    assert cpu is not None  # from /proc while it runs


def test_a_signal_is_reported_as_subprocess_reports_it(server, tmp_path):
    out = tmp_path / "probe.out"
    app = probe(server, out, "wait")
    said(out)
    os.killpg(app.pid, signal.SIGKILL)
    assert app.wait(WAIT) == -signal.SIGKILL


def test_the_stop_ladder_stops_a_forked_module(server, tmp_path):
    out = tmp_path / "probe.out"
    app = probe(server, out, "wait")
    said(out)
    processes.stop([app], wait=5.0)
    assert app.returncode == -signal.SIGINT  # the first rung; uncaught, as Python leaves on it


def test_the_server_leaves_once_closed_and_its_modules_have_left(server, tmp_path):
    out = tmp_path / "probe.out"
    app = probe(server, out, "wait")
    said(out)
    server.close()
    time.sleep(0.5)
    assert server.process.poll() is None  # it waits for its module
    os.killpg(app.pid, signal.SIGTERM)
    assert server.process.wait(timeout=WAIT) == 0


def test_a_dead_server_fails_the_next_spawn_and_its_modules_die_with_it(server, tmp_path):
    out = tmp_path / "probe.out"
    app = probe(server, out, "wait")
    said(out)
    server.process.kill()
    server.process.wait(timeout=WAIT)
    assert app.wait(WAIT) is not None
    with pytest.raises(ForkServerError):
        probe(server, tmp_path / "late.out", "0")
    deadline = time.monotonic() + WAIT
    while os.path.exists(f"/proc/{app.pid}") and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not os.path.exists(f"/proc/{app.pid}")  # PR_SET_PDEATHSIG reached it


def test_turned_off_by_the_variable(monkeypatch):
    monkeypatch.setenv(forkserver.VARIABLE, "0")
    assert forkserver.start(()) is None


def thread_names(pid: int) -> list[str]:
    return [open(f"/proc/{pid}/task/{task}/comm").read().strip() for task in os.listdir(f"/proc/{pid}/task")]


def parent_words(pid: int) -> list[str]:
    ppid = int(open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[1])
    return command_line(ppid)


@pytest.mark.parametrize("forked", [True, False])
def test_a_launch_forks_its_apps_from_the_server_unless_turned_off(launches, community, monkeypatch, forked):
    if not forked:
        monkeypatch.setenv(forkserver.VARIABLE, "0")
    process = launches.start(ALPHA, "--set", f"name={community}", "--set", "pause_at_step=20", "--until", "5")
    wait_registered(community)
    pids = {name: process_with(launches.log_dir, name) for name in ("sim-1", "logger", "clock")}
    parents = {name: parent_words(pid) for name, pid in pids.items()}
    threads = {name: thread_names(pid) for name, pid in pids.items()}
    assert nearsub("clock", community, "resume").returncode == 0
    code, summary, err = finish(process)
    assert code == 0 and summary["outcome"] == "time_limit", err
    for name, words in parents.items():
        assert ("nearsub.common.runtime.forkserver" in words) == forked, (name, words)
        assert ("launch" in words) != forked, (name, words)
    assert summary["cpu"]["sim-1"] > 0.0  # the CPU of every app, forked or not
    for name, names in threads.items():  # Zenoh's receive runtime handed over (bus.APP_RUNTIME)
        assert "app-0" in names and not any(n.startswith(("rx-", "acc-", "net-")) for n in names), (name, names)


def test_a_users_zenoh_runtime_reaches_the_apps_unchanged(launches, community, monkeypatch):
    monkeypatch.setenv("ZENOH_RUNTIME", "(rx: (worker_threads: 3))")
    process = launches.start(ALPHA, "--set", f"name={community}", "--set", "pause_at_step=20", "--until", "5")
    wait_registered(community)
    names = thread_names(process_with(launches.log_dir, "pid-1"))
    assert nearsub("clock", community, "resume").returncode == 0
    code, summary, err = finish(process)
    assert code == 0, err
    assert {"rx-0", "rx-1", "rx-2"} <= set(names), names
