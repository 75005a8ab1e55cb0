"""The 200,000-step soak: zero lost messages in the log and RSS growth under 10 MB for every
process of the mission, measured from /proc at step 2,000 and at the end. Marked `soak` only, so
neither the default run nor `-m reliability` takes it: `pytest -m soak -s` (about 6.5 minutes on
the shared 2-core machine)."""

from __future__ import annotations

import time

import pytest
from test_reliability import settings_args, start_budget

from conftest import ALPHA
from helpers import clock_status, finish, processes_under, wait_registered
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.logfile import read_log

SOAK_STEPS = 200_000
RSS_GROWTH_LIMIT_KB = 10 * 1024
SOAK_WARMUP_STEPS = 2_000  # the first RSS sample: after start-up caches and the first steps


def rss_kb(pid: int) -> int | None:
    """Resident set size from /proc/<pid>/status (VmRSS, kB); None once the process is gone."""
    try:
        for line in open(f"/proc/{pid}/status"):
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def mission_processes(log_dir) -> dict[int, str]:
    """pid -> name of the launcher and every process it started (each names the log folder)."""
    found = {}
    for pid, argv in processes_under(log_dir).items():
        name = argv[argv.index("--instance") + 1] if "--instance" in argv else argv[3] if len(argv) > 3 else str(pid)
        found[pid] = "router" if "nearsub.apps.router" in argv else name
    return found


@pytest.mark.soak
@pytest.mark.timeout(3 * 3600)
def test_a_200000_step_soak_loses_no_message_and_holds_its_memory(launches, community):
    # One far waypoint (50 km at 1.2 m/s: 11.6 h) so the mission runs to its time limit.
    settings = [
        f"name={community}",
        f"time_limit={SOAK_STEPS * 0.05:g}",
        'apps.helm.legs=[{name = "far", points = [[0.0, -50000.0]], speed = 1.2}]',
    ]
    mission = load_mission(ALPHA, settings)
    assert mission.max_steps == SOAK_STEPS
    process = launches.start(ALPHA, *settings_args(settings))
    wait_registered(community, timeout=start_budget(mission))
    while clock_status(community)["step"] < SOAK_WARMUP_STEPS:
        time.sleep(1.0)
    pids = mission_processes(launches.log_dir)
    first = {pid: rss_kb(pid) for pid in pids}
    last = dict(first)
    started = time.monotonic()
    while process.poll() is None:
        for pid in pids:
            if (now := rss_kb(pid)) is not None:
                last[pid] = now
        time.sleep(5.0)
    code, summary, err = finish(process, timeout=60)
    wall = time.monotonic() - started
    assert code == 0 and summary["outcome"] == "time_limit" and summary["steps"] == SOAK_STEPS, err

    contents = read_log(summary["log"])
    steps = {}
    for record in contents.records:
        leaf = record.topic.rsplit("/", 1)[-1]
        if "/remus100/" in record.topic and leaf in ("state", "desired", "input"):
            steps.setdefault(leaf, []).append(record.value()["step"])
    expected = {
        "state": list(range(SOAK_STEPS + 1)),
        "input": list(range(SOAK_STEPS)),
        "desired": list(range(0, SOAK_STEPS, mission.apps.helm.period)),
    }
    lost = {leaf: len(set(expected[leaf]) - set(steps.get(leaf, []))) for leaf in expected}
    growth = {pids[pid]: (last[pid] - first[pid]) for pid in pids if first[pid] is not None}
    print(f"\nsoak: {SOAK_STEPS} steps in {wall:.0f} s after warm-up; lost {lost}; RSS growth kB {growth}")
    assert lost == {leaf: 0 for leaf in expected} and all(steps[leaf] == expected[leaf] for leaf in expected)
    assert not contents.recovered
    assert all(g < RSS_GROWTH_LIMIT_KB for g in growth.values()), growth
