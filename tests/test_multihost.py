"""Two hosts, with credentials: the router in one Linux network namespace, listening on its veth
address, and the launcher with every app in another, connecting across the veth pair
(docs/network.md, "Connecting apps on several hosts"). The trajectory equals the in-process run, which
the single-host tests show equal to a single-host launch."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
from test_reliability import run_budget

from conftest import ALPHA
from helpers import per_topic
from nearsub.common.mission.cores import build_cores
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.lifecycle import Schedule, run_inprocess
from nearsub.common.runtime.messages import Event, decode, encode

pytestmark = [pytest.mark.reliability, pytest.mark.timeout(600)]

PORT = 7447
NEARSUB = [sys.executable, "-m", "nearsub"]


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


@pytest.fixture
def two_hosts():
    """(router namespace, apps namespace, router address): two namespaces joined by a veth pair."""
    if shutil.which("ip") is None:
        pytest.skip("needs the `ip` command (iproute2) to make network namespaces")
    if os.geteuid() != 0:
        pytest.skip("needs root to make network namespaces")
    tag = f"{os.getpid() % 100000}"
    hosts = (f"nsrouter{tag}", f"nsapps{tag}")
    subnet = f"10.{200 + os.getpid() % 50}.{os.getpid() % 250}"
    try:
        for host in hosts:
            _ip("netns", "add", host)
            _ip("-n", host, "link", "set", "lo", "up")
        _ip("link", "add", f"vr{tag}", "netns", hosts[0], "type", "veth", "peer", "name", f"va{tag}", "netns", hosts[1])
        for host, link, address in ((hosts[0], f"vr{tag}", 1), (hosts[1], f"va{tag}", 2)):
            _ip("-n", host, "addr", "add", f"{subnet}.{address}/24", "dev", link)
            _ip("-n", host, "link", "set", link, "up")
        yield hosts[0], hosts[1], f"{subnet}.1"
    finally:
        for host in hosts:
            subprocess.run(["ip", "netns", "del", host], capture_output=True)  # takes the veth pair with it


@contextmanager
def router_on(host: str, endpoint: str, secret: Path, env: dict, timeout: float):
    """`nearsub router` in namespace `host`, listening on `endpoint` with the credentials `secret`
    (made there: what the user copies to the other hosts), until the block ends. Yields the
    line it printed once listening (within `timeout` seconds)."""
    router = subprocess.Popen(
        ["ip", "netns", "exec", host, *NEARSUB, "router", "--listen", endpoint, "--credentials", str(secret)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
        process_group=0,
    )
    try:
        end = time.monotonic() + timeout
        line = ""
        while "router listening on" not in line:
            assert time.monotonic() < end and router.poll() is None, line
            line = router.stdout.readline()
        yield line
    finally:
        os.killpg(router.pid, signal.SIGTERM)
        router.wait(timeout=30)


def host_environment(tmp_path: Path) -> dict:
    """The tests' hosts share this runtime folder and no credentials from the environment."""
    env = dict(os.environ, NEARSUB_RUNTIME_DIR=str(tmp_path / "runtime"))
    env.pop("NEARSUB_CREDENTIALS", None)
    return env


def test_router_on_one_host_and_apps_on_another_with_credentials(two_hosts, tmp_path, community):
    router_host, apps_host, address = two_hosts
    endpoint = f"tcp/{address}:{PORT}"
    secret = tmp_path / "mission.credentials"  # what the user copies to the other host
    env = host_environment(tmp_path)
    settings = [f"name={community}", "time_limit=20", f"network.connect={json.dumps([endpoint])}"]
    mission = load_mission(ALPHA, settings)
    with router_on(router_host, endpoint, secret, env, mission.startup_timeout) as line:
        assert f"router listening on {endpoint}" in line and str(secret) in line, line
        on_apps_host = ["ip", "netns", "exec", apps_host, *NEARSUB]
        stranger = subprocess.run(
            [*on_apps_host, "launch", str(ALPHA), "--log", str(tmp_path / "stranger"), "--set", "startup_timeout=2"]
            + [a for s in settings for a in ("--set", s)],
            capture_output=True,
            text=True,
            env=env,
            timeout=10 * mission.startup_timeout,
        )
        assert stranger.returncode == 1 and f"cannot reach {endpoint}" in stranger.stderr, stranger.stderr

        given = [*settings, f'network.credentials="{secret}"']
        launch = subprocess.run(
            [*on_apps_host, "launch", str(ALPHA), "--log", str(tmp_path / "logs"), "--json"]
            + [a for s in given for a in ("--set", s)],
            capture_output=True,
            text=True,
            env=env,
            timeout=5 * mission.startup_timeout + mission.time_limit * 10,
        )
        assert launch.returncode == 0, launch.stderr
        summary = json.loads(launch.stdout.strip().splitlines()[-1])
        assert summary["outcome"] == "time_limit" and summary["steps"] == mission.max_steps

    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    logged = per_topic(Path(summary["log"]))
    for leaf in ("state", "desired", "input"):
        assert logged[f"remus100/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf


def test_a_fleet_split_over_two_hosts_equals_one_host_bit_for_bit(two_hosts, tmp_path, community):
    """docs/network.md, "A fleet over several hosts": the router and the mission's launch (logger,
    clock, auv1's apps) on one host, auv2's apps joining from the other across the veth pair. The
    log equals the in-process run (which test_fleet_pipeline shows equal to one host's launch),
    the checks between the vehicles included: a close call, then the collision that ends it."""
    from test_fleet import TWO
    from test_fleet_pipeline import MEET

    from nearsub.common.mission.cores import run_mission

    router_host, apps_host, address = two_hosts
    endpoint = f"tcp/{address}:{PORT}"
    secret = tmp_path / "mission.credentials"
    env = host_environment(tmp_path)
    settings = [f"name={community}", MEET, f"network.connect={json.dumps([endpoint])}"]
    mission = load_mission(TWO, settings)
    given = [a for s in [*settings, f'network.credentials="{secret}"'] for a in ("--set", s)]
    budget = 5 * mission.startup_timeout + run_budget(mission)
    with router_on(router_host, endpoint, secret, env, mission.startup_timeout):
        launch = [*NEARSUB, "launch", str(TWO), "--json", *given]
        joined = subprocess.Popen(
            ["ip", "netns", "exec", apps_host, *launch, "--log", str(tmp_path / "b"), "--join", "--vehicles", "auv2"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        main = subprocess.run(
            ["ip", "netns", "exec", router_host, *launch, "--log", str(tmp_path / "a"), "--vehicles", "auv1"],
            capture_output=True,
            text=True,
            env=env,
            timeout=budget,
        )
        out, err = joined.communicate(timeout=budget)
    summary = json.loads(main.stdout.strip().splitlines()[-1])
    joined_summary = json.loads(out.strip().splitlines()[-1])
    reference = run_mission(mission)
    assert reference.outcome == "collision"
    for found in (summary, joined_summary):
        assert (found["outcome"], found["steps"]) == (reference.outcome, reference.steps), (main.stderr, err)
    # Each host ran its own vehicle's apps; only the mission's launch ran the logger and the clock.
    assert {"auv1/helm-1", "auv1/pid-1", "auv1/sim-1", "clock", "logger"} == set(summary["cpu"])
    assert {"auv2/helm-1", "auv2/pid-1", "auv2/sim-1"} == set(joined_summary["cpu"])
    logged = per_topic(Path(summary["log"]))
    for vehicle in ("auv1", "auv2"):
        for leaf in ("state", "desired", "input", "helm"):
            assert logged[f"{vehicle}/{leaf}"] == [encode(m) for m in reference.topic(leaf, vehicle)], (vehicle, leaf)
    assert logged["events/encounters"] == [encode(m) for m in reference.topic("events")]
    # One app_joined event per app, from the mission's launch alone.
    joins = [decode(p, Event, "") for p in per_topic(Path(summary["log"]), skip=())["events/launcher"]]
    assert sorted(e.detail for e in joins if e.kind == "app_joined").count("auv2/sim-1 joined") == 1


def test_the_pipeline_bench_of_a_fleet_over_two_hosts_reports_each_hosts_share(two_hosts, tmp_path):
    """`nearsub bench pipeline --vehicles 4 --host I/2` on each host (docs/network.md): host 1 runs
    the clock, the logger and auv1-auv2 and reports the rate; host 2 joins with auv3-auv4."""
    router_host, apps_host, address = two_hosts
    endpoint = f"tcp/{address}:{PORT}"
    secret = tmp_path / "mission.credentials"
    env = host_environment(tmp_path)
    settings = [f"network.connect={json.dumps([endpoint])}", f'network.credentials="{secret}"']
    bench = [*NEARSUB, "bench", "pipeline", "--vehicles", "4", "--repeats", "1", "--fleet-time", "5", "--json"]
    bench += [a for s in settings for a in ("--set", s)]
    mission = load_mission(ALPHA)
    budget = 3 * (5 * mission.startup_timeout + 5.0 + mission.step_timeout + 15.0)  # three launches each
    with router_on(router_host, endpoint, secret, env, mission.startup_timeout):
        second = subprocess.Popen(
            ["ip", "netns", "exec", apps_host, *bench, "--host", "2/2"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        first = subprocess.run(
            ["ip", "netns", "exec", router_host, *bench, "--host", "1/2"],
            capture_output=True,
            text=True,
            env=env,
            timeout=budget,
        )
        out, err = second.communicate(timeout=budget)
    assert first.returncode == 0 and second.returncode == 0, (first.stderr, err)
    one, two = json.loads(first.stdout), json.loads(out)
    assert one["host"]["vehicles"] == ["auv1", "auv2"] and two["host"]["vehicles"] == ["auv3", "auv4"]
    fleet_one, fleet_two = one["alpha_x4"], two["alpha_x4"]
    assert fleet_one["steps"] == fleet_two["steps"] == 100  # 5 s at dt 0.05
    assert fleet_one["pipeline_steps_per_second"]["median"] > 0
    assert {"clock", "logger"} <= set(fleet_one["cpu_ms_per_step_by_app"])
    assert set(fleet_two["cpu_ms_per_step_by_app"]) == {
        f"auv{k}/{role}-1" for k in (3, 4) for role in ("helm", "pid", "sim")
    }
