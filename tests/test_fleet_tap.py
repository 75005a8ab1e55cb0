"""`nearsub tap` and `nearsub log play` on a mission of two vehicles: a replay of the two-vehicle log
(`logsample.write_fleet_log`), found by name. Timeouts come from the mission's own start-up and
step timeouts, and each test's pytest timeout is the sum of those of its waits (the module's log
counts as one step), so that a slow wait fails with its own message, not pytest's."""

import json
import select
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import pytest
from logsample import write_fleet_log
from test_log_play import STARTUP, STEP, start_player, wait_registered

from conftest import nearsub
from nearsub.common.runtime.processes import stop


@pytest.fixture(scope="module")
def fleet_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("fleettap") / "alpha.mcap"
    write_fleet_log(path, seconds=60.0)
    return path


def listing_taps(community: str) -> list[tuple[str, ...]]:
    """The taps that list the replay, rate alfa's keys and refuse an unknown vehicle. The rates are
    measured over a step timeout: under load the replay may hear of a new subscriber seconds late."""
    return [
        ("tap", "list", community, "--json"),
        ("tap", "hz", community, f"nearsub/{community}/**", "--vehicle", "alfa", "--duration",
         str(STEP), "--json"),
        ("tap", "list", community, "--vehicle", "alfa", "--json"),
        ("tap", "list", community, "--vehicle", "zulu"),
        ("tap", "echo", community, f"nearsub/{community}/*/state", "--vehicle", "zulu",
         "--count", "1", "--timeout", "2"),
        ("tap", "hz", community, f"nearsub/{community}/**", "--vehicle", "zulu", "--duration", "1"),
    ]  # fmt: skip


# The listing taps run at once, each its own process: one start-up timeout per concurrent process.
LISTING_TIMEOUT = len(listing_taps("c")) * STARTUP + STEP


@pytest.mark.timeout(STEP + STARTUP + STARTUP + LISTING_TIMEOUT + STEP + STEP)  # the last: the two stops
def test_tap_lists_the_vehicles_and_echoes_one_of_them(fleet_log, runtime_dir, community):
    # The player starts at the first subscriber: bravo's echo, so that it hears bravo's half of
    # the log (30 s at warp 1) however long the others take to start; the 60 s log outlasts them.
    player = start_player(fleet_log, "--warp", 1, "--name", community, "--wait", STARTUP)
    try:
        wait_registered(community, player)
        argv = ("tap", "echo", community, f"nearsub/{community}/*/state", "--vehicle", "bravo",
                "--count", "5", "--json")  # fmt: skip
        # Unbuffered: its first line read here, the rest by communicate.
        echo = subprocess.Popen([sys.executable, "-m", "nearsub", *argv], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, bufsize=0)  # fmt: skip
        try:
            assert select.select([echo.stdout], [], [], STARTUP)[0], f"no message of bravo within {STARTUP:g} s"
            first = echo.stdout.readline()
            calls = listing_taps(community)
            with ThreadPoolExecutor(len(calls)) as pool:
                runs = pool.map(lambda call: nearsub(*call, timeout=LISTING_TIMEOUT), calls)
                listed, hz, only, unknown, unknown_echo, unknown_hz = runs
            rest, echo_err = echo.communicate(timeout=STEP)
        finally:
            stop([echo])
    finally:
        stop([player])
    assert echo.returncode == 0, echo_err.decode()
    lines = [json.loads(line) for line in (first + rest).splitlines()]
    assert len(lines) == 5 and all(line["key"] == f"nearsub/{community}/bravo/state" for line in lines)
    assert all(line["vehicle"] == "bravo" for line in lines)
    assert hz.returncode == 0, hz.stderr
    assert {json.loads(line)["key"].split("/")[2] for line in hz.stdout.splitlines()} == {"alfa"}
    assert listed.returncode == 0, listed.stderr
    listing = json.loads(listed.stdout)
    assert listing["vehicles"] == ["alfa", "bravo"]
    rows = {row["key"]: row for row in listing["topics"]}
    assert rows[f"nearsub/{community}/bravo/state"]["vehicle"] == "bravo"
    assert only.returncode == 0, only.stderr
    assert {row["vehicle"] for row in json.loads(only.stdout)["topics"]} == {"alfa"}
    for refused, command in ((unknown, "list"), (unknown_echo, "echo"), (unknown_hz, "hz")):
        assert refused.returncode == 2 and refused.stderr == (
            f"nearsub tap {command}: --vehicle zulu: no such vehicle (seen: alfa, bravo)\n"
        ), refused.stderr


@pytest.mark.timeout(STEP + STARTUP + (2 * STARTUP + STEP) + (STARTUP + STEP) + STARTUP)
def test_play_of_one_vehicle_replays_its_keys_and_the_mission_wide_ones(fleet_log, runtime_dir, community):
    player = start_player(fleet_log, "--warp", 0, "--vehicle", "bravo", "--name", community, "--wait", STARTUP)
    try:
        wait_registered(community, player)
        # The player names its message count before it waits for a subscriber. Asked for one more,
        # the tap gets them all (delivery is lossless) and stops when the replay ends.
        count = played_count(player)
        tap = nearsub(
            "tap", "echo", community, f"nearsub/{community}/**", "--count", str(count + 1),
            "--json", timeout=2 * STARTUP + STEP,
        )  # fmt: skip
        player.communicate(timeout=STARTUP + STEP)
    finally:
        stop([player])
    assert tap.returncode == 0, tap.stderr
    assert len(tap.stdout.splitlines()) == count
    ended = f"before mission {community} ended"
    assert tap.stderr == f"nearsub tap echo: {count} of {count + 1} messages on nearsub/{community}/** {ended}\n"
    keys = {json.loads(line)["key"] for line in tap.stdout.splitlines()}
    assert f"nearsub/{community}/bravo/state" in keys and f"nearsub/{community}/clock/end" in keys
    assert not any("/alfa/" in key for key in keys)
    bad = nearsub("log", "play", str(fleet_log), "--vehicle", "zulu", timeout=STARTUP)
    assert bad.returncode == 2 and bad.stderr.startswith("nearsub log play: --vehicle zulu: not a vehicle")


def played_count(player) -> int:
    """The number of messages `nearsub log play` says it is about to play (its "playing N messages" line)."""
    for line in player.stdout:
        if line.startswith("playing "):
            return int(line.split()[1])
    raise AssertionError(f"the player ended without a playing line: {player.communicate()}")


@pytest.mark.timeout(STEP + STARTUP + (2 * STARTUP + STEP) + (STARTUP + STEP) + 2 * STARTUP)
def test_a_short_key_stands_for_that_topic_of_every_vehicle(fleet_log, runtime_dir, community, capsys):
    """`tap echo state` (a new user's first try) follows every vehicle's state of the running
    mission; `log export --topic state` selects them in a log; a word that is no short key is
    one line naming those there are."""
    from nearsub.tools.cli import main

    player = start_player(fleet_log, "--warp", 1, "--name", community, "--wait", STARTUP)
    try:
        wait_registered(community, player)
        echo = nearsub("tap", "echo", community, "state", "--count", "20", "--timeout", str(STARTUP), "--json",
                       timeout=2 * STARTUP + STEP)  # fmt: skip
        quiet = nearsub("tap", "echo", community, "poke", "--count", "1", "--timeout", "1",
                        timeout=STARTUP + STEP)  # fmt: skip
    finally:
        stop([player])
    assert echo.returncode == 0, echo.stderr
    keys = {json.loads(line)["key"] for line in echo.stdout.splitlines()}
    assert keys == {f"nearsub/{community}/alfa/state", f"nearsub/{community}/bravo/state"}
    assert quiet.returncode == 1  # nobody pokes: it says so instead of leaving silently
    assert quiet.stderr == f"nearsub tap echo: 0 of 1 messages on nearsub/{community}/*/poke within 1 s\n"
    assert main(["log", "export", str(fleet_log), "--topic", "state"]) == 0
    exported = {json.loads(line)["topic"] for line in capsys.readouterr().out.splitlines()}
    assert exported == {"nearsub/alpha/alfa/state", "nearsub/alpha/bravo/state"}
    for argv in (("tap", "echo", community, "stat", "--count", "1"),
                 ("log", "export", str(fleet_log), "--topic", "stat")):  # fmt: skip
        refused = nearsub(*argv, timeout=STARTUP)
        assert refused.returncode == 2 and len(refused.stderr.splitlines()) == 1, refused.stderr
        assert "stat: not a short key (state, desired, input, helm, forces, poke, events, end)" in refused.stderr


@pytest.mark.timeout(STEP + STARTUP + (2 * STARTUP + STEP))
def test_tap_watch_keeps_the_newest_value_of_each_key_in_columns(fleet_log, runtime_dir, community):
    """uXMS: several keys and several fields; each key's newest message, a field another topic
    lacks left empty; `tap echo` keeps every --field too (it kept only the last). The watch lasts
    a step timeout: under load the replay may hear of a new subscriber seconds late."""
    player = start_player(fleet_log, "--warp", 1, "--name", community, "--wait", STARTUP)
    try:
        wait_registered(community, player)
        calls = [
            ("tap", "watch", community, "state", "desired", "--field", "x", "--field", "u_d", "--timeout", str(STEP)),
            ("tap", "echo", community, "state", "--field", "x", "--field", "y", "--count", "2"),
        ]  # fmt: skip
        with ThreadPoolExecutor(len(calls)) as pool:
            watch, echo = pool.map(lambda call: nearsub(*call, timeout=len(calls) * STARTUP + STEP), calls)
    finally:
        stop([player])
    assert watch.returncode == 0, watch.stderr
    rows = {row["key"]: row for row in map(json.loads, watch.stdout.splitlines())}
    expected = [f"nearsub/{community}/{v}/{leaf}" for v in ("alfa", "bravo") for leaf in ("desired", "state")]
    assert sorted(rows) == expected
    for vehicle in ("alfa", "bravo"):
        state, desired = rows[f"nearsub/{community}/{vehicle}/state"], rows[f"nearsub/{community}/{vehicle}/desired"]
        assert isinstance(state["fields"]["x"], float) and state["fields"]["u_d"] is None
        assert isinstance(desired["fields"]["u_d"], float) and desired["fields"]["x"] is None
        assert state["vehicle"] == vehicle and state["t"] > 0
    assert echo.returncode == 0, echo.stderr
    assert all(set(json.loads(line)["value"]) == {"x", "y"} for line in echo.stdout.splitlines())
