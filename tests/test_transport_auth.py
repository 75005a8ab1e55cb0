"""Only the mission's own processes get onto its bus: the launcher's router requires the mission's
random credentials (docs/design.md, "Transport"), and a session without them, or with wrong ones,
cannot connect, so it can neither inject a message nor read a topic."""

from __future__ import annotations

import json
import os
import stat

import pytest

from conftest import ALPHA, nearsub
from helpers import finish, wait_registered
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime import credentials
from nearsub.common.runtime.bus import Bus, BusError, Endpoints, Mailbox


def test_credentials_are_private_random_and_refused_when_others_can_read_them(tmp_path):
    first, second = credentials.create(tmp_path / "a"), credentials.create(tmp_path / "b")
    assert stat.S_IMODE(os.stat(first.path).st_mode) == 0o600
    assert (first.user, first.password) != (second.user, second.password)
    assert credentials.load(first.path) == first
    os.chmod(first.path, 0o644)
    with pytest.raises(credentials.CredentialsError, match="mode 644 lets others read it"):
        credentials.load(first.path)
    (tmp_path / "bad").write_text("no separator\n")
    os.chmod(tmp_path / "bad", 0o600)
    with pytest.raises(credentials.CredentialsError, match="one line 'user:password'"):
        credentials.load(tmp_path / "bad")


def test_a_stranger_cannot_reach_a_running_mission_and_its_own_tools_can(launches, community, tmp_path, monkeypatch):
    settings = [f"name={community}", "pause_at_step=100", "time_limit=10"]
    mission = load_mission(ALPHA, settings)
    process = launches.start(ALPHA, *[a for s in settings for a in ("--set", s)])
    entry = wait_registered(community, timeout=5 * mission.startup_timeout)
    path = entry["credentials"]
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    monkeypatch.delenv(credentials.VARIABLE, raising=False)

    wrong = tmp_path / "wrong"
    wrong.write_text(f"{credentials.load(path).user}:not-the-password\n")
    os.chmod(wrong, 0o600)
    for mode, given in [("client", None), ("client", str(wrong)), ("peer", None)]:
        # A peer tries to join the router as a peer would; it too is refused at the handshake.
        stranger = Endpoints(mode, tuple(entry["connect"]), timeout=2.0, credentials=given)
        with pytest.raises(BusError, match="cannot reach"):
            with Bus(stranger):
                pass

    # With the file, a client reads the mission's state, and the tools (which find the file
    # through the registry) control its clock.
    with Bus(Endpoints("client", tuple(entry["connect"]), credentials=path)) as bus:
        mailbox = Mailbox()
        bus.subscribe(f"nearsub/{community}/remus100/state", mailbox)
        status = nearsub("clock", community, "status")
        assert status.returncode == 0 and json.loads(status.stdout)["paused"], status.stderr
        resumed = nearsub("clock", community, "resume")
        assert resumed.returncode == 0, resumed.stderr
        mail = mailbox.get(timeout=mission.step_timeout)
        assert mail is not None and mail.key.endswith("/remus100/state")
    code, summary, err = finish(process, timeout=5 * mission.startup_timeout + mission.time_limit * 5)
    assert code == 0 and summary["outcome"] == "time_limit", err
    assert not os.path.exists(path)  # a mission's credentials end with it


def test_an_unreadable_credentials_file_is_refused_in_one_line(tmp_path, runtime_dir):
    missing = tmp_path / "nowhere"
    setting = ["--set", 'network.connect=["tcp/192.0.2.10:7447"]', "--set", f'network.credentials="{missing}"']
    out = nearsub("launch", str(ALPHA), "--log", str(tmp_path / "logs"), *setting)
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [
        f"nearsub launch: network.credentials: credentials file {missing}: No such file or directory"
    ]


def test_a_runtime_folder_others_can_write_is_refused_in_one_line(tmp_path, runtime_dir):
    os.chmod(runtime_dir, 0o777)
    out = nearsub("launch", str(ALPHA), "--log", str(tmp_path / "logs"), "--until", "1")
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert f"runtime folder {runtime_dir} has mode 777" in out.stderr and f"chmod 700 {runtime_dir}" in out.stderr


def test_links_planted_in_the_runtime_folder_are_never_written_through(tmp_path, runtime_dir, community):
    from nearsub.tools.support import registry

    targets = {suffix: tmp_path / f"target{suffix}" for suffix in (".lock", ".json", ".credentials")}
    for suffix, target in targets.items():
        target.write_text("precious\n")
        (runtime_dir / f"{community}{suffix}").symlink_to(target)
    with pytest.raises(LookupError, match=f"{community}.lock is a symbolic link"):
        registry.claim(community)
    out = nearsub("launch", str(ALPHA), "--set", f"name={community}", "--log", str(tmp_path / "logs"))
    assert out.returncode == 2 and "is a symbolic link" in out.stderr and len(out.stderr.splitlines()) == 1
    registry.register(community, ["tcp/127.0.0.1:7447"], str(tmp_path / "log.mcap"))
    assert json.loads((runtime_dir / f"{community}.json").read_text())["community"] == community
    assert not (runtime_dir / f"{community}.json").is_symlink()
    credentials.create(registry.credentials_path(community))
    assert not registry.credentials_path(community).is_symlink()
    assert all(target.read_text() == "precious\n" for target in targets.values())
