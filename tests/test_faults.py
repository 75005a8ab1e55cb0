"""Bad input and faults: nothing hangs silently, nothing is lost, every log closes."""

import json
import os
import signal
import subprocess
import sys
import time

import msgpack
import pytest
from mcap.reader import make_reader

from conftest import ALPHA, nearsub
from helpers import finish, log_path, process_with, wait_registered
from nearsub.common.runtime.logfile import LogWriter, read_log

pytestmark = pytest.mark.timeout(180)


app_pid = process_with


def no_processes_left(log_dir):
    out = subprocess.run(["pgrep", "-f", str(log_dir)], capture_output=True, text=True).stdout
    return out.strip() == ""


def test_malformed_messages_are_rejected_and_logged(launches, community):
    # The mission pauses itself before step 100, so it is still running however long each
    # `nearsub tap pub` takes to start on a busy machine; the test resumes it when done.
    process = launches.start(ALPHA, "--set", f"name={community}", "--set", "pause_at_step=100", "--until", "30")
    wait_registered(community)
    key = f"nearsub/{community}/remus100/state"
    raw = nearsub("tap", "pub", community, key, "--raw-hex", "c1ffee")
    malformed = json.dumps({"step": 3, "t": 0.1, "source": "sim", "u": "fast"})
    bad = nearsub("tap", "pub", community, key, malformed, "--no-validate")
    refused = nearsub("tap", "pub", community, key, json.dumps({"u": float("inf")}))
    assert raw.returncode == 0 and bad.returncode == 0, (raw.stderr, bad.stderr)
    assert refused.returncode == 2 and "'u'" in refused.stderr  # tap pub validates by default
    assert nearsub("clock", community, "resume").returncode == 0
    code, summary, err = finish(process)
    assert code == 0 and summary["outcome"] == "time_limit", err
    records = read_log(log_path(summary)).records
    errors = [r.value()["detail"] for r in records if "/events/" in r.topic and r.value()["kind"] == "error"]
    assert any("not valid msgpack" in e for e in errors)
    assert any("'u'" in e and "fast" in e for e in errors), errors
    invalid = [r for r in records if r.topic == key + "#invalid"]
    assert len(invalid) == 2  # both bad payloads kept, byte for byte
    assert {r.data for r in invalid} == {
        bytes.fromhex("c1ffee"),
        msgpack.packb({"step": 3, "t": 0.1, "source": "sim", "u": "fast"}),
    }


def test_killed_app_is_reported_and_the_log_is_closed(launches, community):
    process = launches.start(ALPHA, "--set", f"name={community}", "--warp", "5", "--until", "120")
    wait_registered(community)
    time.sleep(1.0)
    os.kill(app_pid(launches.log_dir, "sim-1"), signal.SIGKILL)
    killed_at = time.monotonic()
    code, summary, err = finish(process)
    assert code != 0
    assert "app sim-1 exited with code -9 at step" in err
    assert f"(its output: {log_path(summary).parent / 'sim-1.out'})" in err  # where to look
    assert summary["outcome"] == "error" and summary["failed_app"] == "sim-1"
    contents = read_log(log_path(summary))
    assert not contents.recovered and contents.metadata["outcome"]["outcome"] == "error"
    assert time.monotonic() - killed_at < 20
    time.sleep(0.5)
    assert no_processes_left(launches.log_dir)


def test_report_comes_within_five_seconds(launches, community):
    process = launches.start(ALPHA, "--set", f"name={community}", "--warp", "5", "--until", "120")
    wait_registered(community)
    os.kill(app_pid(launches.log_dir, "pid-1"), signal.SIGKILL)
    killed_at = time.monotonic()
    line = process.stderr.readline()
    assert "app pid-1 exited" in line
    assert time.monotonic() - killed_at < 5.0
    process.communicate(timeout=60)


def test_stalled_app_is_named_by_the_clock(launches, community):
    process = launches.start(
        ALPHA, "--set", f"name={community}", "--set", "step_timeout=2", "--warp", "5", "--until", "120"
    )
    wait_registered(community)
    os.kill(app_pid(launches.log_dir, "pid-1"), signal.SIGSTOP)
    code, summary, err = finish(process)
    assert code == 1
    assert summary["outcome"] == "stalled"
    assert "app 'pid' did not finish step" in summary["reason"] and "within 2 s" in summary["reason"]
    assert read_log(log_path(summary)).metadata["outcome"]["outcome"] == "stalled"
    time.sleep(0.5)
    assert no_processes_left(launches.log_dir)


def test_ctrl_c_stops_everything_and_closes_the_log(launches, community):
    process = launches.start(ALPHA, "--set", f"name={community}", "--warp", "5", "--until", "120")
    wait_registered(community)
    process.send_signal(signal.SIGINT)
    code, summary, err = finish(process)
    assert code == 130 and summary["outcome"] == "interrupted"
    assert not read_log(log_path(summary)).recovered
    time.sleep(0.5)
    assert no_processes_left(launches.log_dir)


def test_two_communities_on_one_router_do_not_cross_talk(launches, tmp_path):
    port = subprocess.run(
        [sys.executable, "-c", "from nearsub.common.runtime.bus import free_tcp_port; print(free_tcp_port())"],
        capture_output=True,
        text=True,
    ).stdout.strip()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = subprocess.Popen([sys.executable, "-m", "nearsub", "router", "--listen", endpoint], process_group=0)
    try:
        time.sleep(0.5)
        connect = f'network.connect=["{endpoint}"]'
        a = launches.start(ALPHA, "--set", "name=alpha_one", "--set", connect, "--until", "30")
        b = launches.start(ALPHA, "--set", "name=alpha_two", "--set", connect, "--until", "30")
        for process, name in ((a, "alpha_one"), (b, "alpha_two")):
            code, summary, err = finish(process, timeout=120)
            assert code == 0 and summary["outcome"] == "time_limit", err
            topics = read_log(log_path(summary)).topics()
            assert topics and all(topic.startswith(f"nearsub/{name}/") for topic in topics)
            assert summary["steps"] == 600
    finally:
        os.killpg(router.pid, signal.SIGKILL)
        router.wait()


def inputs_log(path, count: int = 20000) -> LogWriter:
    """A log of `count` pid inputs, steps 0.. in order, not yet finished."""
    writer = LogWriter(path)
    for i in range(count):
        writer.write(
            "nearsub/x/remus100/input",
            msgpack.packb({"step": i, "t": i * 0.05, "source": "pid", "X_prop": 1.0, "delta_r": 0.0}),
            i * 0.05,
        )
    return writer


def test_a_log_cut_short_is_readable_up_to_its_last_chunk(tmp_path):
    path = tmp_path / "cut.mcap"
    writer = inputs_log(path)
    writer._file.flush()  # a crash: the writer never finishes
    size = path.stat().st_size
    with open(path, "r+b") as f:
        f.truncate(size - 100)
    contents = read_log(path)
    assert contents.recovered and contents.damage.startswith("the file was not finished (a crash)")
    steps = [msgpack.unpackb(r.data)["step"] for r in contents.records]
    assert steps == list(range(len(steps))) and len(steps) > 15000


@pytest.mark.parametrize("damage", ["one bit", "a zeroed block"])
def test_a_damaged_chunk_of_a_finished_log_is_skipped_and_the_rest_kept(tmp_path, damage):
    path = tmp_path / "log.mcap"
    inputs_log(path).finish()
    with open(path, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    hit = chunks[len(chunks) // 2]
    data = bytearray(path.read_bytes())
    middle = hit.chunk_start_offset + hit.chunk_length // 2
    if damage == "one bit":  # still decompresses: only the chunk's CRC tells
        data[middle] ^= 0x01
    else:
        data[middle : middle + 512] = bytes(512)
    path.write_bytes(bytes(data))
    contents = read_log(path)
    steps = [msgpack.unpackb(r.data)["step"] for r in contents.records]
    assert contents.recovered and contents.damage.startswith(f"1 of {len(chunks)} chunks damaged (bytes ")
    assert 0 < 20000 - len(steps) < 20000 / len(chunks) * 2  # one chunk's messages, no more
    assert steps == sorted(steps) and steps[-1] == 19999  # the chunks after it are kept
    info = nearsub("log", "info", str(path), "--json")
    assert info.returncode == 0 and json.loads(info.stdout)["damage"] == contents.damage


def test_a_flood_of_invalid_messages_keeps_the_first_of_each_key_and_counts_the_rest(launches, community):
    from nearsub.apps.logger import INVALID_KEPT
    from nearsub.common.runtime.bus import Bus, Endpoints

    process = launches.start(ALPHA, "--set", f"name={community}", "--set", "pause_at_step=100", "--until", "30")
    entry = wait_registered(community)
    key, sent = f"nearsub/{community}/remus100/state", 50 * INVALID_KEPT
    with Bus(Endpoints("client", tuple(entry["connect"]), credentials=entry["credentials"])) as bus:
        flood = bus.publisher(key)  # lossless: every one reaches the logger
        for _ in range(sent):
            flood.put(b"\xc1")  # never valid msgpack
    assert nearsub("clock", community, "resume").returncode == 0
    code, summary, err = finish(process)
    assert code == 0 and summary["outcome"] == "time_limit", err
    records = read_log(log_path(summary)).records
    errors = [r for r in records if "/events/logger" in r.topic and r.value()["kind"] == "error"]
    assert len([r for r in records if r.topic == key + "#invalid"]) == INVALID_KEPT and len(errors) == INVALID_KEPT
    assert "further invalid messages are only counted" in errors[-1].value()["detail"]
    info = nearsub("log", "info", str(log_path(summary)), "--json")
    assert json.loads(info.stdout)["invalid_dropped"] == {key: sent - INVALID_KEPT}, info.stdout[-500:]
    text = nearsub("log", "info", str(log_path(summary))).stdout
    assert f"{sent - INVALID_KEPT} more invalid messages on {key} counted, not kept" in " ".join(text.split())
