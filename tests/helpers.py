"""Reading logs back for comparisons."""

from __future__ import annotations

import json
import math
import os
import time
from collections import defaultdict
from pathlib import Path

from nearsub.common.mission.schema import Mission
from nearsub.common.runtime.logfile import read_log

# A launch's own bound on its apps coming up (the mission's default startup_timeout): the waits
# below derive from it instead of a number of their own.
STARTUP_TIMEOUT = Mission.model_fields["startup_timeout"].default


def log_path(summary: dict) -> Path:
    return Path(summary["log"])


WALL_CLOCK_TOPICS = ("/events/launcher", "/status/", "/control/", "/reply/", "/clock/tick")


def per_topic(path: Path, skip=WALL_CLOCK_TOPICS) -> dict[str, list[bytes]]:
    """Payload bytes of each topic in arrival order, leaving out the topics whose content depends
    on the wall clock: the clock's grants (how far ahead it lets the apps run), app status and
    join/leave events, and control traffic."""
    topics = defaultdict(list)
    for record in read_log(path).records:
        if not any(part in record.topic for part in skip):
            topics[record.topic.split("/", 2)[2]].append(record.data)
    return dict(topics)


def wait_registered(community: str, timeout: float = STARTUP_TIMEOUT) -> dict:
    """Block until `nearsub launch` has registered the mission (its apps are all up)."""
    from nearsub.tools.support import registry

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        running = registry.running()
        if community in running:
            return running[community]
        time.sleep(0.05)
    raise AssertionError(f"mission {community} did not register within {timeout:g} s")


def finish(process, timeout: float = 120) -> tuple[int, dict, str]:
    """Wait for a `nearsub launch --json` process: exit code, summary, stderr."""
    out, err = process.communicate(timeout=timeout)
    return process.returncode, json.loads(out.strip().splitlines()[-1]), err


def command_line(pid) -> list[str]:
    """The words of a process's command line. An app forked by the launcher's fork server
    (common/runtime/forkserver.py) shows its command as one title with spaces, not NUL-separated."""
    return open(f"/proc/{pid}/cmdline").read().replace("\0", " ").split()


def processes_under(log_dir) -> dict[int, list[str]]:
    """pid -> argv of the processes whose command line mentions `log_dir` (only this test's)."""
    found = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            argv = command_line(entry)
        except OSError:
            continue
        if any(str(log_dir) in a for a in argv):
            found[int(entry)] = argv
    return found


def process_with(log_dir, marker: str) -> int:
    """The pid of the process started as instance `marker` (`--instance marker`) or as module
    `marker` (`-m marker`) whose command line mentions `log_dir` (so only this test's processes
    match). A bare argument would also match `--after surrogate` of the apps that wait for it."""
    for pid, argv in processes_under(log_dir).items():
        if any(
            flag in ("--instance", "-m") and value == marker for flag, value in zip(argv[:-1], argv[1:], strict=True)
        ):
            return pid
    raise AssertionError(f"no process with {marker} under {log_dir}")


def clock_status(community: str) -> dict:
    """`nearsub clock <community> status` as a dict."""
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-m", "nearsub", "clock", community, "status"], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def wait_paused(community: str, timeout: float = STARTUP_TIMEOUT) -> dict:
    """The clock's status once it has paused; fails after `timeout` wall seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        status = clock_status(community)
        if status["paused"]:
            return status
        time.sleep(0.2)
    raise AssertionError(f"the clock of {community} did not pause")


def poke_while_paused(launches, path: Path, community: str, assignment: str):
    """Launch the mission at `path` (it pauses itself at step 100), poke `assignment` into its
    remus100's helm, check the helm confirms it from step 100, resume; returns (mission, process)."""
    from conftest import nearsub
    from nearsub.common.mission.schema import load_mission

    mission = load_mission(path, [f"name={community}"])
    process = launches.start(str(path), "--set", f"name={community}")
    wait_registered(community, timeout=mission.startup_timeout)
    wait_paused(community, timeout=mission.startup_timeout)
    nobody = nearsub("poke", community, assignment, "--vehicle", "nosuch")  # refused at once, not after 10 s
    assert nobody.returncode == 2 and nobody.stderr.startswith("nearsub poke: no vehicle 'nosuch' in mission")
    poked = nearsub("poke", community, assignment, "--vehicle", "remus100")
    assert poked.returncode == 0, poked.stderr
    assert "remus100/helm: operator poke from step 100" in poked.stdout  # the vehicle, the app, the step
    assert nearsub("clock", community, "resume").returncode == 0
    return mission, process


# Cross-machine comparisons of a mission's messages: numpy, OpenBLAS and numba pick their SIMD kernels
# per CPU, so the last bits differ between machines (transcendental functions, BLAS products), and a
# closed-loop mission carries them along without growing them. Measured: with a random third of every
# numpy transcendental result moved by one ulp, alpha's states moved by 3e-14 m over 8266 steps; numpy
# on its baseline SSE kernels against AVX2 moved overtake_stern_nuv's forces by 6e-12 N, its states by
# 1e-14. A real change moves them far more: alpha's heading kp 1 % higher moved its track by 1e-2 m
# and its psi_d by 1e-3 rad, its first waypoint moved 1 cm its track by 6e-3 m. So every float of a
# trace is compared to |a - b| <= TRACE_ATOL + TRACE_RTOL |b|, everything else (counts, events' steps
# and text, outcome, steps) exactly.
TRACE_RTOL = 1e-7
TRACE_ATOL = 1e-9
TRACE_SAMPLES = 40  # messages sampled per topic, evenly over the run, and the last one


def mission_trace(result, topics: tuple[str, ...] | None = None) -> dict:
    """What tests/data pins of an in-process run (`run_inprocess`'s result) to compare across
    machines: how it ended, each (app, topic)'s message count, every event, and TRACE_SAMPLES
    messages of every other topic (of `topics` only, when given), sampled evenly with the last one."""
    by_key = defaultdict(list)
    for app, topic, message in result.messages:
        if topics is None or topic in topics:
            by_key[f"{app}/{topic}"].append(message)
    samples, events = {}, {}
    for key, messages in by_key.items():
        if key.endswith("/events"):
            events[key] = [message.model_dump() for message in messages]
        else:
            every = max(1, len(messages) // TRACE_SAMPLES)
            samples[key] = [message.model_dump() for message in [*messages[::every], messages[-1]]]
    return {
        "outcome": result.outcome,
        "reason": result.reason,
        "steps": result.steps,
        "counts": {key: len(messages) for key, messages in by_key.items()},
        "events": events,
        "samples": samples,
    }


def trace_differences(actual, reference, where: str = "") -> list[str]:
    """Where `actual` (a `mission_trace`) differs from `reference` (one read back from JSON): floats
    beyond TRACE_ATOL + TRACE_RTOL |reference|, anything else at all."""
    if isinstance(reference, dict) and isinstance(actual, dict):
        if actual.keys() != reference.keys():
            return [f"{where}: keys {sorted(actual)} != {sorted(reference)}"]
        return [d for key in reference for d in trace_differences(actual[key], reference[key], f"{where}/{key}")]
    if isinstance(reference, list | tuple) and isinstance(actual, list | tuple):
        if len(actual) != len(reference):
            return [f"{where}: {len(actual)} items != {len(reference)}"]
        return [
            d
            for i, (a, b) in enumerate(zip(actual, reference, strict=True))
            for d in trace_differences(a, b, f"{where}[{i}]")
        ]
    if isinstance(reference, float) and isinstance(actual, float | int) and not isinstance(actual, bool):
        if actual == reference or (math.isnan(reference) and math.isnan(actual)):
            return []
        if abs(actual - reference) <= TRACE_ATOL + TRACE_RTOL * abs(reference):
            return []
    elif actual == reference and type(actual) is type(reference):
        return []
    return [f"{where}: {actual!r} != {reference!r}"]


def helm_trace(mission_path: Path) -> dict:
    """The `mission_trace` of a mission's helm decisions as tests/data/helm-decisions.json pins them:
    its desired, helm and state topics and its events. `python tests/pin_helm_decisions.py NAME...`
    writes them after a deliberate physics change."""
    from nearsub.common.mission.cores import run_mission
    from nearsub.common.mission.schema import load_mission

    return mission_trace(run_mission(load_mission(mission_path)), ("desired", "helm", "state", "events"))


def run_with_poke(mission, values: dict, at_step: int):
    """The mission in-process with an operator's poke of `values` due at `at_step`."""
    from nearsub.common.mission.cores import build_cores
    from nearsub.common.runtime.lifecycle import Schedule, run_inprocess
    from nearsub.common.runtime.messages import Poke

    poke = Poke(step=0, t=0.0, source="operator", values=values)
    schedule = Schedule(mission.periods())
    return run_inprocess(
        build_cores(mission), schedule, mission.dt, mission.max_steps, operator=[("helm", "poke", at_step, poke)]
    )


def wait_until(condition, timeout: float, what: str) -> None:
    """Poll `condition` until it holds; fails saying `what` did not happen within `timeout` s."""
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"{what} within {timeout:g} s")
        time.sleep(0.02)


def page_urls(line: str) -> tuple[str, str]:
    """(control URL, read-only URL) of the viewer's line `...: http://...?token=C (read-only: http://...?token=V)`."""
    words = line.split()
    return next(w for w in words if w.startswith("http://")), words[-1].rstrip(")")


def socket_url(page: str) -> str:
    """The websocket of the viewer's page at `page`, with the page's token."""
    from urllib.parse import urlsplit

    url = urlsplit(page)
    return f"ws://{url.netloc}/ws?{url.query}"
