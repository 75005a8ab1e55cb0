"""A fork server: one process imports what the apps share, once, and forks every app from it.

Each app started as `python -m nearsub.apps.X` imports numpy, pydantic, Zenoh's bindings and the
mission schema again (0.3-0.4 CPU-s each, 0.8 for the surrogate server): on two cores the seven
processes of a mission spent about a second of its start-up importing. The launcher starts this
server beside the router, so the imports overlap the router's own start, then asks it for each
app (`ForkServer.spawn`); a forked app starts with its modules loaded, as an Android zygote's
children or Python's multiprocessing "forkserver" do.

A forked app is what `processes.spawn_app` starts, but for its parent: stdin /dev/null, stdout
and stderr into the launcher's file, a process group of its own, the environment the launcher
had when it asked, the module run as `__main__`, and a process title that reads like the command
line it stands for (`ps`, `pgrep -f`). The server is single-threaded when it forks (one BLAS
thread, no Zenoh session opened: importing the bindings starts no thread), which is what makes
forking it safe.

Protocol, over a Unix socket pair: the launcher sends a JSON request with the output file's
descriptor attached (SCM_RIGHTS); the server answers {"pid": N} (or {"error": text}) and, when
the app exits, {"exited": N, "code": C, "cpu": S} (C as subprocess gives it: negative for a
signal; S its user + system CPU seconds, from wait4, since the server reaps it at once). When the
launcher closes its end, the server waits for its apps to leave, then exits; when the launcher
dies, the server dies with it (PR_SET_PDEATHSIG) and its apps get SIGTERM (theirs).
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import runpy
import selectors
import signal
import socket
import subprocess
import sys
import time
import warnings
from collections.abc import Iterable, Mapping, Sequence
from typing import IO

from nearsub.common.runtime.processes import (
    cpu_seconds,
    leave,
    module_command,
    prepare_process,
    single_blas_thread,
)

try:  # a forked app's `ps` line reads as the command it stands for (pyproject.toml says why)
    import setproctitle
except ImportError:  # the apps run the same without it
    setproctitle = None

# "0" in the launcher's environment: start every app as its own `python -m` process instead.
VARIABLE = "NEARSUB_FORK_SERVER"
MAX_MESSAGE = 1 << 20
EXIT_REPORT_WAIT = 2.0  # wall seconds between the server reaping an app and its report reaching us, at most


class ForkServerError(RuntimeError):
    """The fork server is gone or answered with an error."""


class ForkedApp:
    """A forked app as the launcher sees it: the parts of `subprocess.Popen` that `processes.stop`
    and the launcher use (pid, poll, wait, returncode), plus the CPU seconds reported at exit."""

    def __init__(self, server: ForkServer, pid: int):
        self.server, self.pid = server, pid
        self.returncode: int | None = None
        self.cpu: float | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            self.server.collect()
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        end = None if timeout is None else time.monotonic() + timeout
        while self.poll() is None:
            if end is not None and time.monotonic() > end:
                raise subprocess.TimeoutExpired(f"pid {self.pid}", timeout)
            self.server.collect(wait=0.02)
        return self.returncode


class ForkServer:
    """The launcher's end: starts the server, which loads `preload` while the caller goes on, and
    asks it for apps. Each entry of `preload` is a module to import or "module:function", a
    function of no arguments to call once (to fill a module's caches the apps share)."""

    def __init__(self, preload: Sequence[str]):
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        process = subprocess.Popen(
            [sys.executable, "-u", "-m", __name__, str(theirs.fileno()), *preload],
            pass_fds=[theirs.fileno()],
            stdin=subprocess.DEVNULL,
            env=single_blas_thread(dict(os.environ)),
            process_group=0,  # a Ctrl-C reaches the launcher, which stops the apps in order, not the server
        )
        theirs.close()
        self._attach(ours, process)

    def _attach(self, ours: socket.socket, process: subprocess.Popen) -> None:
        self.socket, self.process = ours, process
        self.apps: dict[int, ForkedApp] = {}
        self.exits: dict[int, tuple[int, float]] = {}  # pid -> (code, cpu) reported by the server
        self.buffer = b""
        self.replies: list[dict] = []

    def spawn(
        self, module: str, args: Iterable[str], output: IO[bytes], timeout: float, env: Mapping[str, str] | None = None
    ) -> ForkedApp:
        """Fork `python -m MODULE ARGS` (an app: nearsub.apps.X) with stdout and stderr into
        `output` and the environment `env` (default: this process's at the request), as
        `processes.spawn_app` starts one. The first answer waits for the preload;
        a server that has not answered within `timeout` wall seconds is killed (so that it never
        forks the app late, beside the one the caller then starts itself)."""
        environment = single_blas_thread(dict(os.environ if env is None else env))
        request = {"module": module, "args": list(args), "env": environment}
        try:
            socket.send_fds(self.socket, [json.dumps(request).encode() + b"\n"], [output.fileno()])
        except OSError as exc:
            raise ForkServerError(f"the fork server is gone ({exc}; exit code {self.process.poll()})") from None
        end = time.monotonic() + timeout
        try:
            self._await_reply(module, timeout, end)
        except KeyboardInterrupt:  # the app is being forked: stop it, or nobody would (the caller never sees it)
            self._await_reply(module, timeout, end)
            if pid := self.replies.pop(0).get("pid"):
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(pid, signal.SIGTERM)
            raise
        reply = self.replies.pop(0)
        if "error" in reply:
            raise ForkServerError(f"the fork server could not start {module}: {reply['error']}")
        forked = self.apps[reply["pid"]] = ForkedApp(self, reply["pid"])
        self._settle()
        return forked

    def _await_reply(self, module: str, timeout: float, end: float) -> None:
        while not self.replies:
            if time.monotonic() > end:
                self.process.kill()
                raise ForkServerError(f"the fork server did not fork {module} within {timeout:g} s")
            self.collect(wait=0.05)

    def _settle(self) -> None:
        for pid in [pid for pid in self.exits if pid in self.apps]:
            app = self.apps[pid]
            app.returncode, app.cpu = self.exits.pop(pid)

    def collect(self, wait: float = 0.0) -> None:
        """Read what the server has said (spawn replies, exits), waiting up to `wait` seconds."""
        if wait > 0:
            self.socket.settimeout(wait)
        else:
            self.socket.setblocking(False)
        try:
            data = self.socket.recv(65536)
        except (BlockingIOError, TimeoutError):
            return
        except OSError:
            data = b""
        if not data:  # the server is gone: its apps died with it (PDEATHSIG)
            self._server_gone()
            return
        self.buffer += data
        *lines, self.buffer = self.buffer.split(b"\n")
        for line in lines:
            message = json.loads(line)
            if "exited" in message:  # kept until `spawn` has made its app: it may arrive with the pid
                self.exits[message["exited"]] = message["code"], message["cpu"]
                self._settle()
            else:
                self.replies.append(message)

    def _server_gone(self) -> None:
        for app in self.apps.values():
            if app.returncode is None:
                app.returncode = -signal.SIGTERM  # what PR_SET_PDEATHSIG sent it
        if not self.replies:
            self.replies.append({"error": f"the fork server exited with code {self.process.poll()}"})

    def close(self) -> None:
        """Let the server leave once its apps have (it stops forking at once)."""
        self.socket.close()
        try:
            self.process.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            pass  # it stays until its last app leaves; PDEATHSIG ends it with the launcher


def start(preload: Sequence[str]) -> ForkServer | None:
    """A fork server preloading `preload` (`ForkServer`), or None where it is turned off
    (`VARIABLE`) or this is not Linux (no pidfd)."""
    if os.environ.get(VARIABLE, "1") == "0" or not hasattr(os, "pidfd_open"):
        return None
    return ForkServer(preload)


def process_cpu(process) -> float | None:
    """User + system CPU seconds of a started app so far: from /proc while it runs, and, for a
    forked app the fork server has reaped, the figure it reported at the exit."""
    seconds = cpu_seconds(process.pid)
    if seconds is None and isinstance(process, ForkedApp):
        # Reaped by the server, whose report of the exit (with the figure) may still be on its way.
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(timeout=EXIT_REPORT_WAIT)
        seconds = process.cpu
    return seconds


# ------------------------------------------------------------------------------- the server
def _run_app(request: dict, output: int, conn: socket.socket, selector: selectors.BaseSelector) -> None:
    """In the forked child: become the app, then exit with its code (never returns)."""
    code = 1
    try:
        selector.close()
        conn.close()
        os.setpgid(0, 0)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.dup2(output, 1)
        os.dup2(output, 2)
        os.close(null)
        os.close(output)
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        if setproctitle is not None:  # before the environment changes: it reuses that memory
            setproctitle.setproctitle(" ".join(module_command(request["module"], request["args"])))
        os.environ.clear()
        os.environ.update(request["env"])
        module = request["module"]
        sys.argv = [module, *request["args"]]
        # The server preloaded the app's module; running it again as __main__ is the point, so
        # runpy's warning about that would only reach a user's screen when the app fails.
        warnings.filterwarnings("ignore", r".*found in sys\.modules after import of package", RuntimeWarning)
        runpy.run_module(module, run_name="__main__", alter_sys=True)
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        if not isinstance(exc.code, int | None):
            print(exc.code, file=sys.stderr)
    except KeyboardInterrupt:  # as Python itself leaves on one: killed by SIGINT
        code = -signal.SIGINT
    except BaseException:
        import traceback

        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
            if code == -signal.SIGINT:
                signal.signal(signal.SIGINT, signal.SIG_DFL)
                os.kill(os.getpid(), signal.SIGINT)
        finally:
            os._exit(code if code >= 0 else 1)


def serve(conn: socket.socket, preload: Sequence[str]) -> int:
    prepare_process()  # SIGTERM when the launcher dies; our apps then get theirs
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    for entry in preload:
        name, _, function = entry.partition(":")
        module = importlib.import_module(name)
        if function:
            getattr(module, function)()
    selector = selectors.DefaultSelector()
    selector.register(conn, selectors.EVENT_READ, None)
    buffer, fds, listening = b"", [], True
    children: dict[int, int] = {}  # pidfd -> pid

    def send(message: dict) -> None:
        try:
            conn.sendall(json.dumps(message).encode() + b"\n")
        except OSError:
            pass  # the launcher has gone; the apps still run to their end

    while listening or children:
        for key, _ in selector.select():
            if key.data is not None:  # an app exited
                pid = key.data
                selector.unregister(key.fd)
                os.close(key.fd)
                del children[key.fd]
                _, status, usage = os.wait4(pid, 0)
                send({"exited": pid, "code": os.waitstatus_to_exitcode(status), "cpu": usage.ru_utime + usage.ru_stime})
                continue
            try:
                data, received, _, _ = socket.recv_fds(conn, MAX_MESSAGE, 16)
            except ConnectionResetError:  # the launcher closed before reading our last reply
                data, received = b"", []
            fds += received
            if not data:
                listening = False
                selector.unregister(conn)
                continue
            buffer += data
            *lines, buffer = buffer.split(b"\n")
            for line in lines:
                request, output = json.loads(line), fds.pop(0)
                try:
                    pid = os.fork()
                except OSError as exc:
                    os.close(output)
                    send({"error": str(exc)})
                    continue
                if pid == 0:
                    _run_app(request, output, conn, selector)
                os.close(output)
                try:
                    os.setpgid(pid, pid)  # also here: a stop sent at once must find the group
                except OSError:
                    pass  # the child got there first
                pidfd = os.pidfd_open(pid)
                children[pidfd] = pid
                selector.register(pidfd, selectors.EVENT_READ, pid)
                send({"pid": pid})
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    conn = socket.socket(fileno=int(argv[0]))
    return serve(conn, argv[1:])


if __name__ == "__main__":
    leave(main())  # without the interpreter's teardown of what it preloaded (0.4 s with numba and scipy)
