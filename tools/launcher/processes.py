"""The processes a launch starts: each app forked from the fork server (or started as its own
process when there is none), the router, their liveliness at start-up, the order they are
stopped in and their CPU. Each child gets the environment in `Processes.env`, never this
process's own changed."""

from __future__ import annotations

import json
import os
import subprocess
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from nearsub.common.mission.schema import Mission
from nearsub.common.runtime import credentials as mission_credentials
from nearsub.common.runtime import keys
from nearsub.common.runtime.forkserver import ForkServer, ForkServerError, process_cpu
from nearsub.common.runtime.processes import spawn_app, stop


class LaunchError(RuntimeError):
    """A launch or a mission that cannot go on; `app` names the process at fault, if one is."""

    def __init__(self, text: str, app: str | None = None):
        super().__init__(text)
        self.app = app


@dataclass
class Child:
    instance: str
    role: str
    process: subprocess.Popen
    output: Path
    retiring: bool = False

    def exited(self, when: str) -> str:
        """The line that says it left (`when`: "at step N", "during start-up") and where its output is."""
        return f"app {self.instance} exited with code {self.process.returncode} {when} (its output: {self.output})"

    def tail(self, lines: int = 12) -> str:
        try:
            text = self.output.read_text(errors="replace").splitlines()
        except OSError:
            return ""
        return "\n".join(f"    {line}" for line in text[-lines:])


# What the fork server loads before it forks the apps (common/runtime/forkserver.py): what every
# lock-stepped app, the logger and the clock import at start-up; near a submarine also the
# surrogate server's GP stack and the sim's interaction, the LF's and the helm's compiled kernels
# (from numba's cache) and the LF's submarine field table (from nearsub's cache), which the sim,
# the helms and the server would otherwise each load.
APP_PRELOAD = ("nearsub.apps.shell", "nearsub.apps.logger", "nearsub.apps.clock", "nearsub.common.mission.cores")
SURROGATE_PRELOAD = (
    "nearsub.apps.surrogate",
    "nearsub.apps.services",
    "nearsub.common.surrogate.model",
    "nearsub.common.surrogate.interaction",
    "nearsub.tools.support.kernels:compile_kernels",
    "nearsub.common.hydro.low_fidelity:submarine_field",
)


def fork_preload(mission: Mission) -> tuple[str, ...]:
    return APP_PRELOAD + (SURROGATE_PRELOAD if mission.needs_surrogate else ())


def spawn_router(
    folder: Path, timeout: float, credentials: Path, interrupted=lambda: False
) -> tuple[subprocess.Popen, list[str]]:
    """Start a router on loopback port 0 (output in `folder`/router.out) that admits only the
    holders of fresh random `credentials` (written there, mode 0600), and wait, up to `timeout`
    wall seconds, for the ready file in which it names the endpoints it listens on. A router that
    exits first, or stays silent, is a LaunchError naming it; `interrupted()` ends the wait."""
    ready, output = folder / "router.json", folder / "router.out"
    mission_credentials.create(credentials)
    argv = ["--listen", "tcp/127.0.0.1:0", "--ready-file", str(ready), "--with-parent"]
    argv += ["--credentials", str(credentials)]
    with open(output, "wb") as out:
        router = spawn_app("router", argv, out)
    deadline = time.monotonic() + timeout
    try:
        while not ready.exists():
            code = router.poll()
            if code is not None:
                lines = output.read_text(errors="replace").strip().splitlines()
                said = f": {lines[-1]}" if lines else ""
                raise LaunchError(f"the router exited with code {code} before listening{said}", app="router")
            if time.monotonic() > deadline:
                raise LaunchError(f"the router did not report its endpoint within {timeout:g} s", app="router")
            if interrupted():
                raise KeyboardInterrupt
            time.sleep(0.02)
        return router, list(json.loads(ready.read_text()))
    except BaseException:
        stop([router], grace=0.0)
        raise


class Processes:
    """The processes of one launch: the apps by instance (`children`), the router, the fork server
    and the companions (`launch --view`, `--foxglove`). Every app started gets `env`, set once the
    router's endpoints are known (`bus.app_environment`); `say` reports each start."""

    def __init__(self, run_dir: Path, startup_timeout: float, say: Callable[[str], None]):
        self.run_dir = run_dir
        self.run_file = run_dir / "run.json"
        self.startup_timeout = startup_timeout
        self.say = say
        self.env: dict[str, str] = dict(os.environ)
        self.children: dict[str, Child] = {}
        self.router: subprocess.Popen | None = None
        self.forks: ForkServer | None = None  # the apps' pre-imported parent (runtime/forkserver.py)
        self.companions: list[subprocess.Popen] = []
        self.instance_counter = Counter()

    def spawn(self, module: str, instance: str, role: str, extra: list[str] = ()) -> Child:
        output = self.run_dir / f"{instance}.out"  # a fleet vehicle's apps: in its own folder
        output.parent.mkdir(exist_ok=True)
        args = ["--run", str(self.run_file), "--instance", instance, *extra]
        with open(output, "wb") as out:
            process = None
            if self.forks is not None:
                try:
                    process = self.forks.spawn(f"nearsub.apps.{module}", args, out, self.startup_timeout, self.env)
                except ForkServerError as exc:
                    self.say(f"{exc}; starting the apps as their own processes")
                    self.forks = None
            if process is None:
                process = spawn_app(module, args, out, self.env)
        child = Child(instance, role, process, output)
        self.children[instance] = child
        self.say(f"started {instance} (pid {process.pid})")
        return child

    def next_instance(self, role: str) -> str:
        self.instance_counter[role] += 1
        return f"{role}-{self.instance_counter[role]}"

    def ended(self, instance: str) -> bool:
        """A process that exited with code 0 left after the mission end (an app can end the
        mission at step 0, before the launcher has seen every token): the supervision reads the end."""
        child = self.children.get(instance)
        return child is not None and child.process.poll() == 0

    def wait_alive(
        self, bus, community: str, wanted: list[tuple[str, str]], timeout: float, interrupted=lambda: False
    ) -> None:
        """Wait for the liveliness tokens of (role, instance) pairs; fail naming the missing ones."""
        deadline = time.monotonic() + timeout
        while True:
            alive = set(bus.alive(keys.all_alive(community), timeout=0.5))
            missing = [
                inst for role, inst in wanted if keys.alive(community, role, inst) not in alive and not self.ended(inst)
            ]
            if not missing:
                return
            for inst in missing:
                child = self.children.get(inst)
                code = None if child is None else child.process.poll()
                # 0: it ended the mission since `missing` was read (a sim refusing its
                # interaction settings at step 0); the supervision reads that end and its reason.
                if code is not None and code != 0:
                    raise LaunchError(f"{child.exited('during start-up')}\n{child.tail()}", inst)
            if time.monotonic() > deadline:
                raise LaunchError(f"apps did not come up within {timeout:g} s: {', '.join(missing)}")
            if interrupted():
                raise KeyboardInterrupt
            time.sleep(0.02)

    def router_lost(self) -> bool:
        return self.router is not None and self.router.poll() is not None

    def killed(self) -> list[Child]:
        """The apps that died (a signal), and the logger or server that left with an error."""
        return [
            c
            for c in self.children.values()
            if not c.retiring
            and (code := c.process.poll()) is not None
            and (code < 0 or (code != 0 and c.role in ("logger", "surrogate")))
        ]

    def cpu_now(self) -> dict[str, float]:
        """CPU seconds of each process so far, by instance (the router as "router")."""
        processes = {c.instance: c.process for c in self.children.values()}
        if self.router is not None:
            processes["router"] = self.router
        cpu = {name: process_cpu(p) for name, p in processes.items()}
        return {name: seconds for name, seconds in cpu.items() if seconds is not None}

    def stop_all(self) -> None:
        """Let apps leave on their own (the lock-stepped ones exit on the mission end), then
        escalate; the surrogate server serves until they have gone (the sim's last step may still
        ask it about the final state, `Iteration.then`); the logger closes its file last."""
        grace = 0.0 if self.router_lost() else 3.0  # without the router the launcher's end reaches no app
        stop(self.companions, grace=0.0)
        stop([c.process for c in self.children.values() if c.role not in ("logger", "surrogate")], grace=grace)
        stop([c.process for c in self.children.values() if c.role == "surrogate"], grace=0.0)
        stop([c.process for c in self.children.values() if c.role == "logger"], grace=5.0 if grace else 0.0)

    def close(self) -> None:
        """Stop everything, the router and the fork server last."""
        self.stop_all()
        if self.router is not None:
            stop([self.router], grace=0.0)
        if self.forks is not None:
            self.forks.close()
