"""`nearsub log play`: a log republished onto the bus equals the logged streams message for
message, and tools find the replay by its community name. Timeouts come from the mission's own
startup and step timeouts."""

import json
import subprocess
import sys
import time
from collections import defaultdict

import pytest
from logsample import write_sample_log

from conftest import ALPHA, nearsub
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.bus import Bus, Endpoints, Mailbox
from nearsub.common.runtime.logfile import INVALID_SUFFIX, read_log
from nearsub.common.runtime.processes import stop
from nearsub.tools.support import registry

MISSION = load_mission(ALPHA, [])
STARTUP, STEP = MISSION.startup_timeout, MISSION.step_timeout


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("play") / "alpha.mcap"
    write_sample_log(path)
    return path


def start_player(*args):
    argv = [sys.executable, "-m", "nearsub", "log", "play", *map(str, args)]
    return subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, process_group=0)


def wait_registered(community, player):
    end = time.monotonic() + STARTUP
    while time.monotonic() < end:
        entry = registry.running().get(community)
        if entry is not None:
            return entry
        assert player.poll() is None, player.communicate()
        time.sleep(0.05)
    raise AssertionError(f"the replay did not register {community} within {STARTUP:g} s")


def test_replay_equals_the_log_message_for_message(log, runtime_dir, community):
    logged = defaultdict(list)
    for r in sorted(read_log(log).records, key=lambda r: r.log_time):
        logged[r.topic.removesuffix(INVALID_SUFFIX).replace("nearsub/alpha/", f"nearsub/{community}/", 1)].append(
            bytes(r.data)
        )
    total = sum(len(v) for v in logged.values())
    player = start_player(log, "--warp", 0, "--name", community, "--wait", STARTUP)
    try:
        entry = wait_registered(community, player)
        received = defaultdict(list)
        with Bus(
            Endpoints("client", tuple(entry["connect"]), timeout=STARTUP, credentials=entry["credentials"])
        ) as bus:
            mailbox = Mailbox()
            bus.subscribe(f"nearsub/{community}/**", mailbox)
            end = time.monotonic() + STARTUP + STEP
            count = 0
            while count < total and time.monotonic() < end:
                mail = mailbox.get(timeout=0.1)
                if mail is not None:
                    received[mail.key].append(mail.payload)
                    count += 1
        out, err = player.communicate(timeout=STARTUP + STEP)
    finally:
        stop([player])
    assert player.returncode == 0, err
    state = f"nearsub/{community}/remus100/state"
    assert len(logged[state]) == 202  # 201 states of 10 s at 20 Hz and the undecodable payload
    assert received[state] == logged[state]
    assert dict(received) == dict(logged)
    assert out.splitlines()[0] == f"router {entry['connect'][0]} (started)"


def test_tap_finds_the_replay_by_name_with_a_window_and_a_warp(log, runtime_dir, community):
    player = start_player(
        log, "--warp", 2, "--from", 5, "--to", 6, "--topic", "nearsub/alpha/*/state", "--name", community,
        "--wait", STARTUP,
    )  # fmt: skip
    try:
        wait_registered(community, player)
        key = f"nearsub/{community}/remus100/state"
        tap = nearsub("tap", "echo", community, key, "--count", "21", "--json", timeout=STARTUP + STEP)
        out, err = player.communicate(timeout=STARTUP + STEP)
    finally:
        stop([player])
    assert tap.returncode == 0, tap.stderr
    times = [json.loads(line)["t"] for line in tap.stdout.splitlines()]
    assert times == pytest.approx([5.0 + 0.05 * i for i in range(21)])
    assert player.returncode == 0, err
    wall = float(out.splitlines()[-1].split(" in ")[1].split()[0])
    assert wall >= 0.5 * 0.95  # 1 simulated second at warp 2
    assert community not in registry.running()  # the replay unregisters when it ends


@pytest.mark.parametrize(
    "args, named",
    [
        (["--name", "a b"], "--name 'a b'"),
        (["--topic", "nearsub/other/**"], "--topic nearsub/other/**"),
        (["--from", "5", "--to", "2"], "--to 2"),
        (["--connect", "garbage"], "connect endpoint 'garbage' is not <protocol>/<address>"),
        (["--connect", "tcp/127.0.0.1:99999"], "connect endpoint 'tcp/127.0.0.1:99999' needs a port 1-65535"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(log, runtime_dir, args, named):
    out = nearsub("log", "play", str(log), *args, timeout=STARTUP)
    assert out.returncode == 2 and out.stderr.startswith(f"nearsub log play: {named}"), out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


def test_a_running_mission_name_is_refused(log, runtime_dir, community):
    with registry.claim(community):
        out = nearsub("log", "play", str(log), "--name", community, timeout=STARTUP)
    assert out.returncode == 2 and f"--name {community}: a mission of that name is running" in out.stderr
