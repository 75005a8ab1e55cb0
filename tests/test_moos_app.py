"""`nearsub moos sim` as a process against a MOOSDB stand-in speaking the MOOS wire protocol
(pymoos2's packets, as the real MOOSDB answers a synchronous client): it registers for the
DESIRED_* variables, flies the thrust it is given, counts a malformed rudder in its AppCast, and
exits 1 with one line when the DB goes away. A bad .moos line and a missing extra are one line and
exit 2. The same app against the real MOOSDB: tests/test_moos_ivp.py."""

from __future__ import annotations

import socket
import struct
import subprocess
import sys
import threading
import time

import pytest

pytest.importorskip("pymoos2", reason="the moos extra (pip install 'nearsub[moos]')")

from pymoos2.core import constants as c  # noqa: E402
from pymoos2.core.MOOSCommPkt import pack, unpack  # noqa: E402
from pymoos2.core.MOOSMsg import MOOSMsg  # noqa: E402

WAIT = 60.0  # wall seconds for the app to start (imports) and fly: generous on a loaded machine


class StandInDB:
    """One client at a time: the handshake, then every packet answered with the mail queued for
    it (or a NULL message); every notification kept in `posted`."""

    def __init__(self):
        self.server = socket.socket()
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.server.bind(("127.0.0.1", 0))
        self.server.listen(1)
        self.port = self.server.getsockname()[1]
        self.posted: list[MOOSMsg] = []
        self.registered: set[str] = set()
        self.outbox: list[MOOSMsg] = []
        self.lock = threading.Lock()
        self.connection = None
        threading.Thread(target=self.serve, daemon=True).start()

    def read(self, n: int) -> bytes:
        data = b""
        while len(data) < n:
            chunk = self.connection.recv(n - len(data))
            if not chunk:
                raise ConnectionError
            data += chunk
        return data

    def packet(self) -> list[MOOSMsg]:
        head = self.read(4)
        return unpack(head + self.read(struct.unpack("<i", head)[0] - 4))

    def serve(self):
        try:
            self.connection, _ = self.server.accept()
            self.read(c.PROTOCOL_STRING_BUFFER_SIZE)
            self.packet()
            welcome = MOOSMsg(c.MSG_WELCOME, "", val=0.0)
            welcome.community = "standin"
            self.connection.sendall(pack([welcome]))
            while True:
                for message in self.packet():
                    with self.lock:
                        if message.msg_type == c.MSG_REGISTER:
                            self.registered.add(message.key)
                        elif message.msg_type == c.MSG_NOTIFY:
                            self.posted.append(message)
                with self.lock:
                    reply, self.outbox = self.outbox or [MOOSMsg(c.MSG_NULL, "")], []
                self.connection.sendall(pack(reply))
        except OSError:
            return

    def send(self, key: str, value) -> None:
        kind = {"val": float(value)} if isinstance(value, float) else {"sval": str(value)}
        with self.lock:
            self.outbox.append(MOOSMsg(c.MSG_NOTIFY, key, **kind))

    def latest(self, key: str):
        with self.lock:
            found = [m for m in self.posted if m.key == key]
        return found[-1] if found else None

    def close(self):
        for s in (self.connection, self.server):
            if s is not None:
                s.shutdown(socket.SHUT_RDWR) if s is self.connection else None
                s.close()


def wait_for(predicate, what: str, process):
    deadline = time.monotonic() + WAIT
    while time.monotonic() < deadline:
        if predicate():
            return
        assert process.poll() is None, f"the sim left early: {process.communicate()[1]}"
        time.sleep(0.05)
    pytest.fail(f"{what}: not within {WAIT:g} s")


def moos_file(tmp_path, port: int, block: str = "") -> str:
    path = tmp_path / "standin.moos"
    path.write_text(
        f"ServerHost = 127.0.0.1\nServerPort = {port}\nCommunity = standin\nMOOSTimeWarp = 10\n\n"
        f"ProcessConfig = nearsub_sim\n{{\n  AppTick = 10\n  start_pos = x=5, y=-20, heading=90\n{block}}}\n"
    )
    return str(path)


def start(path: str):
    return subprocess.Popen(
        [sys.executable, "-m", "nearsub", "moos", "sim", path],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def test_the_sim_flies_the_desired_thrust_counts_a_malformed_rudder_and_leaves_when_the_db_goes(tmp_path):
    db = StandInDB()
    process = start(moos_file(tmp_path, db.port))
    try:
        wait_for(lambda: db.latest("NAV_X") is not None, "the first NAV_X", process)
        assert {"DESIRED_THRUST", "DESIRED_RUDDER", "DESIRED_ELEVATOR"} <= db.registered
        assert db.latest("NAV_X").val == 5.0 and db.latest("NAV_HEADING").val == 90.0
        db.send("DESIRED_THRUST", 24.0)
        db.send("DESIRED_RUDDER", "hard-a-port")
        wait_for(lambda: (db.latest("NAV_SPEED") or MOOSMsg()).val > 0.3, "NAV_SPEED above 0.3 m/s", process)
        assert db.latest("NAV_X").val > 5.0  # heading east
        assert db.latest("NAV_Y").val == pytest.approx(-20.0, abs=1e-6)  # no rudder taken
        wait_for(
            lambda: "run_warnings=1:malformed DESIRED_RUDDER" in (db.latest("APPCAST") or MOOSMsg(sval="x")).sval,
            "the malformed rudder in the AppCast",
            process,
        )
        db.close()
        _, err = process.communicate(timeout=WAIT)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 1
    assert err.strip().count("\n") == 0 and "lost the MOOSDB at 127.0.0.1" in err, err


def test_a_bad_moos_line_is_one_line_and_exit_2(tmp_path):
    path = moos_file(tmp_path, 9, "  turn_rate = 95\n")
    done = subprocess.run(
        [sys.executable, "-m", "nearsub", "moos", "sim", path], capture_output=True, text=True, timeout=WAIT
    )
    assert done.returncode == 2
    assert done.stderr.startswith(f"nearsub moos sim: {path}:10: turn_rate = 95: unknown parameter (known: ")
    assert done.stderr.count("\n") == 1


def test_no_moosdb_at_start_is_one_line_and_exit_1(tmp_path, monkeypatch):
    from nearsub.apps import moos_sim

    monkeypatch.setattr(moos_sim, "CONNECT_TIMEOUT", 0.5)
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    from nearsub.tools.cli import main

    assert main(["moos", "sim", moos_file(tmp_path, port)]) == 1


def test_without_the_extra_moos_is_one_line_saying_what_to_install(tmp_path, monkeypatch, capsys):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "pymoos2" else real(name, *a))
    from nearsub.tools.cli import main

    assert main(["moos", "sim", moos_file(tmp_path, 9)]) == 2
    assert capsys.readouterr().err == "nearsub moos: MOOS support needs its extra: pip install 'nearsub[moos]'\n"


def test_moos_watch_posts_a_launched_missions_vehicle_waypoints_and_track(launches, community, tmp_path):
    """`nearsub moos watch` follows a launched alpha (by its run file) and posts what pMarineViewer
    draws: the vehicle's NODE_REPORT, the waypoints and the track; it leaves when the DB goes."""
    import os
    import signal
    from pathlib import Path

    from conftest import ALPHA
    from helpers import wait_registered
    from nearsub.common.mission.schema import load_mission

    mission = load_mission(ALPHA)
    startup, step = mission.startup_timeout, mission.step_timeout
    launches.start(ALPHA, "--set", f"name={community}", "--warp", "5", "--until", "300")
    entry = wait_registered(community, timeout=2 * startup + step)
    db = StandInDB()
    run = str(Path(entry["log"]).parent / "run.json")
    argv = [sys.executable, "-m", "nearsub", "moos", "watch", community, "--run", run, "--db", f"127.0.0.1:{db.port}"]
    watch = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, process_group=0)
    try:
        deadline = time.monotonic() + 2 * startup
        while db.latest("NODE_REPORT") is None or "NAME=remus100" not in db.latest("NODE_REPORT").sval:
            assert time.monotonic() < deadline, f"no NODE_REPORT within {2 * startup:g} s"
            assert watch.poll() is None, watch.communicate()
            time.sleep(0.05)
        report = dict(part.split("=", 1) for part in db.latest("NODE_REPORT").sval.split(","))
        assert report["TYPE"] == "uuv" and float(report["LENGTH"]) == mission.vehicle_model.length
        assert abs(float(report["TIME"]) - time.time()) < 60  # MOOS time at warp 1: the wall clock
        seglist = db.latest("VIEW_SEGLIST").sval
        assert seglist.startswith("pts={0.00,-20.00:60.00,-40.00:") and "label=remus100_track" in seglist
        assert db.latest("VIEW_POINT").sval.startswith("x=")
        db.close()
        _, err = watch.communicate(timeout=2 * step)
    finally:
        if watch.poll() is None:
            os.killpg(watch.pid, signal.SIGKILL)
            watch.wait()
    assert watch.returncode == 1 and err == "nearsub moos watch: lost the MOOSDB\n"
