"""The processes nearsub starts: their environment, how they are spawned and how they are stopped.

Standard library only, so the command line can use it before anything imports numpy.
"""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, MutableMapping
from contextlib import contextmanager
from typing import IO, NoReturn

# One BLAS thread per process: nearsub is many small processes on few cores, where OpenBLAS's
# threads made a GP fit 25x and a 10,000-point batch 5x slower (measured on a 2-core machine), and
# results that pass through a dense solve then agree to the last bit between a process and the
# workers it starts. The variables are read when numpy loads, so set them before that.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
# And one numba thread in every process nearsub starts (apps, workers): the compiled LF and GP
# kernels spread a batch's rows over numba's threads, which only a sweep in one process (the
# `nearsub` command itself) should do; processes, not threads, scale the rest.
NUMBA_THREAD_VARIABLE = "NUMBA_NUM_THREADS"

# Stopping escalates per process group, as ros2 launch does: SIGINT lets an app end cleanly (the
# logger closes its file), SIGTERM, then SIGKILL for one that ignores both.
STOP_LADDER = (signal.SIGINT, signal.SIGTERM, signal.SIGKILL)
STOP_WAIT = 5.0  # wall seconds between two rungs


def single_blas_thread(environ: MutableMapping[str, str] = os.environ, numba: bool = True) -> MutableMapping[str, str]:
    """Ask for one BLAS thread in `environ` (this process's environment by default, which the
    processes it starts inherit) and return it; with `numba`, one numba thread too. A variable the
    user has set is left as it is."""
    for name in BLAS_THREAD_VARIABLES + ((NUMBA_THREAD_VARIABLE,) if numba else ()):
        environ.setdefault(name, "1")
    return environ


# glibc's allocator thresholds for local Dask workers. Dask's nanny sets MALLOC_TRIM_THRESHOLD_
# to 64 KiB, which also freezes glibc's mmap threshold at 128 KiB: every numpy temporary above it
# is mapped, faulted in and unmapped again (a K = 32 envelope spent a fifth of its CPU in page
# faults: 9.7 M minor faults, 130 k with these values). The workers are short-lived, so holding
# freed memory costs little. A value the user has set is kept.
MALLOC_THRESHOLDS = {"MALLOC_TRIM_THRESHOLD_": str(256 << 20), "MALLOC_MMAP_THRESHOLD_": str(64 << 20)}


def keep_malloc_arenas(environ: MutableMapping[str, str] = os.environ) -> MutableMapping[str, str]:
    """Raise glibc's trim and mmap thresholds in `environ` for the worker processes it starts
    (`MALLOC_THRESHOLDS`); variables the user has set are left as they are."""
    for name, value in MALLOC_THRESHOLDS.items():
        environ.setdefault(name, value)
    return environ


class Terminated(SystemExit):
    """SIGTERM (the stop ladder's second rung, or the launcher's death), raised in the main thread
    so that `with` blocks close the session and files; its code is 128 + the signal."""


def prepare_process() -> None:
    """Exit cleanly on SIGTERM (Terminated, so `with` blocks close the session and files), and ask
    Linux to send SIGTERM when the launcher dies, so no app outlives it. SIGINT, the ladder's first rung,
    raises KeyboardInterrupt even when the launcher was started as a background job of a script,
    which starts every child with SIGINT ignored."""

    def handler(signum, frame):
        raise Terminated(128 + signum)

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    parent_death_signal()()


def parent_death_signal() -> Callable[[], None]:
    """A function asking Linux to send its caller SIGTERM when the thread that started the caller
    dies (PR_SET_PDEATHSIG, kept across exec): for `prepare_process`, and as a `preexec_fn`
    (libc is looked up here, before a fork, so that the child only makes the call)."""
    try:
        prctl = ctypes.CDLL("libc.so.6", use_errno=True).prctl
    except (OSError, AttributeError):
        return lambda: None  # not Linux: the launcher's liveliness token still stops the apps
    return lambda: prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


def leave(code: int) -> NoReturn:
    """End an app process with `code` once its sessions and files are closed, skipping the
    interpreter's teardown of numpy, pydantic and Zenoh (about 0.1 s of CPU per process, measured),
    which every mission paid seven times at its end."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def module_command(module: str, args: Iterable[str]) -> list[str]:
    """`python -u -m MODULE ARGS` with this interpreter: how an app is started (and how a forked
    one is shown, `forkserver`)."""
    return [sys.executable, "-u", "-m", module, *args]


def spawn_app(
    app: str, args: Iterable[str], output: IO[bytes] | int, env: Mapping[str, str] | None = None
) -> subprocess.Popen:
    """Start `python -m nearsub.apps.<app> ARGS` with one BLAS thread, stdin closed, stdout and
    stderr into `output`, in a process group of its own so that `stop` reaches the workers it
    starts too; its environment is `env` (default: this process's)."""
    return subprocess.Popen(
        module_command(f"nearsub.apps.{app}", args),
        stdout=output,
        stderr=subprocess.STDOUT,
        stdin=subprocess.DEVNULL,
        env=single_blas_thread(dict(os.environ if env is None else env)),
        process_group=0,
    )


def cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds of process `pid` so far (also of one that has exited and not
    yet been reaped), from /proc; None where there is no /proc or no such process."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime


def stop(
    processes: Iterable[subprocess.Popen],
    grace: float = 0.0,
    ladder: tuple[signal.Signals, ...] = STOP_LADDER,
    wait: float = STOP_WAIT,
) -> None:
    """Stop process groups: give them `grace` seconds to leave on their own, then send each rung
    of `ladder` to the groups still alive, `wait` seconds apart. Returns when all have gone, or
    `wait` seconds after the last rung."""
    processes = list(processes)
    deadline = time.monotonic() + grace
    for signum in (None, *ladder):
        alive = [p for p in processes if p.poll() is None]
        if not alive:
            return
        if signum is not None:
            for p in alive:
                try:
                    os.killpg(p.pid, signum)
                    os.killpg(p.pid, signal.SIGCONT)  # a stopped (SIGSTOP) process must see it too
                except ProcessLookupError:
                    pass
            deadline = time.monotonic() + wait
        while time.monotonic() < deadline and any(p.poll() is None for p in alive):
            time.sleep(0.02)


class SchedulerError(LookupError):
    """The Dask scheduler a command was given cannot be reached: bad input, one line (the command
    line prints a LookupError so)."""


@contextmanager
def task_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[object | None]:
    """Where `completed` runs its tasks: None (this process) when neither is given, else a Dask
    client of the running cluster at `scheduler`, or of a local cluster of `workers` processes on
    127.0.0.1 with one thread and one BLAS thread each (a task's numpy work holds a core; more
    processes, not threads, scale it)."""
    if scheduler is None and not workers:
        yield None
        return
    from distributed import Client, LocalCluster

    single_blas_thread()  # inherited by the local workers
    cluster = None
    if scheduler is None:
        keep_malloc_arenas()
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, host="127.0.0.1", dashboard_address=None, processes=True
        )
    try:
        try:
            client = Client(scheduler or cluster)
        except (OSError, TimeoutError) as exc:  # distributed's connect failures
            raise SchedulerError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({exc})") from None
        with client:
            yield client
    finally:
        if cluster is not None:
            cluster.close()


def completed(client: object | None, function: Callable, items: Iterable) -> Iterator[tuple[int, object]]:
    """(index, function(item)) for every item, in completion order, on `client` (`task_client`)."""
    items = list(items)
    if client is None:
        for index, item in enumerate(items):
            yield index, function(item)
        return
    from distributed import as_completed

    futures = client.map(function, items, pure=False)
    index_of = {future.key: index for index, future in enumerate(futures)}
    for future in as_completed(futures):
        yield index_of[future.key], future.result()
