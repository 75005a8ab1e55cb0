"""The process policies: one BLAS thread in what nearsub starts, app spawning, the stop ladder."""

import os
import signal
import socket
import subprocess
import sys
import time

from nearsub.common.runtime import processes

# A child that ignores SIGINT and SIGTERM, says so, and would otherwise sleep for a minute.
STUBBORN = (
    "import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); "
    "signal.signal(signal.SIGTERM, signal.SIG_IGN); print('ready', flush=True); time.sleep(60)"
)


def test_single_blas_thread_sets_the_variables_and_keeps_a_users_choice():
    env = processes.single_blas_thread({"OMP_NUM_THREADS": "4"})
    assert env == {
        "OPENBLAS_NUM_THREADS": "1",
        "OMP_NUM_THREADS": "4",
        "MKL_NUM_THREADS": "1",
        "NUMBA_NUM_THREADS": "1",
    }
    # The `nearsub` command keeps numba's threads for its own sweeps (tools/cli.py).
    assert "NUMBA_NUM_THREADS" not in processes.single_blas_thread({}, numba=False)


def _malloc_thresholds():
    return {name: os.environ.get(name) for name in processes.MALLOC_THRESHOLDS}


def test_local_dask_workers_keep_the_raised_malloc_thresholds(monkeypatch):
    """Dask's nanny sets its own MALLOC_TRIM_THRESHOLD_; the workers must see nearsub's (or the user's)."""
    for name in processes.MALLOC_THRESHOLDS:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("MALLOC_MMAP_THRESHOLD_", "1048576")  # a user's own value is kept
    with processes.task_client(workers=1) as client:
        seen = client.submit(_malloc_thresholds).result()
    assert seen == {"MALLOC_TRIM_THRESHOLD_": str(256 << 20), "MALLOC_MMAP_THRESHOLD_": "1048576"}


def test_single_blas_thread_reaches_a_child(monkeypatch):
    for name in processes.BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    processes.single_blas_thread()
    code = f"import os; print(' '.join(os.environ[n] for n in {processes.BLAS_THREAD_VARIABLES!r}))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["1", "1", "1"]


def test_spawned_app_has_one_blas_thread_and_a_process_group_of_its_own(monkeypatch):
    for name in processes.BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    process = processes.spawn_app("router", ["--listen", f"tcp/127.0.0.1:{port}", "--with-parent"], subprocess.DEVNULL)
    try:
        while b"nearsub.apps.router" not in open(f"/proc/{process.pid}/cmdline", "rb").read():
            time.sleep(0.01)  # until the child has exec'd: before, /proc shows the parent's environment
        text = open(f"/proc/{process.pid}/environ").read()
        environ = dict(item.split("=", 1) for item in text.split("\0") if "=" in item)
        group = os.getpgid(process.pid)
    finally:
        processes.stop([process], wait=2.0)
    assert {name: environ.get(name) for name in processes.BLAS_THREAD_VARIABLES} == dict.fromkeys(
        processes.BLAS_THREAD_VARIABLES, "1"
    )
    assert group == process.pid
    assert "OPENBLAS_NUM_THREADS" not in os.environ  # the parent's own environment is left alone


def test_stop_escalates_to_sigkill_for_a_process_ignoring_sigint_and_sigterm():
    process = subprocess.Popen([sys.executable, "-c", STUBBORN], stdout=subprocess.PIPE, text=True, process_group=0)
    assert process.stdout.readline().strip() == "ready"
    start = time.monotonic()
    processes.stop([process], wait=0.5)
    elapsed = time.monotonic() - start
    assert process.returncode == -signal.SIGKILL
    assert 1.0 <= elapsed < 5.0  # two ignored rungs of 0.5 s each, then the kill


# Python's own SIGINT handler, even when the test runs as a background job of a non-interactive
# shell (which starts it, and so every child, with SIGINT ignored).
SLEEPER = (
    "import signal, time; signal.signal(signal.SIGINT, signal.default_int_handler); "
    "print('ready', flush=True); time.sleep(60)"
)


def test_stop_returns_at_once_when_the_first_rung_is_heeded():
    process = subprocess.Popen(
        [sys.executable, "-c", SLEEPER],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        process_group=0,
    )
    # A SIGINT that lands while the interpreter is still starting may be lost; wait until it runs.
    assert process.stdout.readline().strip() == "ready"
    start = time.monotonic()
    processes.stop([process], wait=10.0)
    assert process.returncode == -signal.SIGINT  # Python leaves by SIGINT on an uncaught KeyboardInterrupt
    assert time.monotonic() - start < 5.0


def test_stop_waits_out_the_grace_for_a_process_that_leaves_on_its_own():
    process = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(0.3)"], process_group=0)
    processes.stop([process], grace=10.0, wait=0.1)
    assert process.returncode == 0


def test_an_app_heeds_sigint_though_its_launcher_started_it_with_sigint_ignored():
    app = (
        "import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); "
        "from nearsub.common.runtime.processes import prepare_process; prepare_process(); "
        "print('ready', flush=True); time.sleep(60)"
    )
    process = subprocess.Popen(
        [sys.executable, "-c", app], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, process_group=0
    )
    assert process.stdout.readline().strip() == "ready"
    processes.stop([process], wait=10.0)
    assert process.returncode == -signal.SIGINT


def test_a_scheduler_nobody_listens_on_is_one_line_naming_it():
    """`--scheduler` of envelope, train and cfd run: an address without a Dask scheduler is bad
    input (a LookupError: one line and exit 2 on the command line), not a traceback."""
    import dask
    import pytest

    with socket.socket() as s:  # a free port, closed again: nothing listens there
        s.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{s.getsockname()[1]}"
    with dask.config.set({"distributed.comm.timeouts.connect": "2s"}):
        with pytest.raises(processes.SchedulerError, match=f"--scheduler {address}: cannot reach") as caught:
            with processes.task_client(scheduler=address):
                pass
    assert isinstance(caught.value, LookupError) and len(str(caught.value).splitlines()) == 1


def test_a_router_leaves_on_signals_that_arrive_back_to_back(tmp_path):
    """The stop ladder's SIGINT and SIGTERM, and a user's repeated Ctrl-C, may land while the
    router's handler of the one before is still running: it must leave, not deadlock in its own
    handler (a router of a killed test's player outlived it that way)."""
    ready = tmp_path / "router.json"
    process = processes.spawn_app(
        "router", ["--listen", "tcp/127.0.0.1:0", "--ready-file", str(ready)], subprocess.DEVNULL
    )
    try:
        deadline = time.monotonic() + 60.0
        while not ready.exists() and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert ready.exists(), "the router did not start"
        for _ in range(200):
            for signum in (signal.SIGINT, signal.SIGTERM):
                if process.poll() is None:
                    process.send_signal(signum)
        process.wait(timeout=10.0)
    finally:
        processes.stop([process], wait=2.0)
    assert process.returncode == 0
