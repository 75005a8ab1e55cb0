"""The launcher hands every process it starts the mission's environment (connect timeout,
credentials, link, Zenoh runtime) and never changes its own: a second launch in the same process
(`nearsub bench` launches many) inherits nothing of the first, here not the first's credentials
file, which is gone once the first has ended."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from conftest import ALPHA
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime import credentials
from nearsub.common.runtime.bus import CONNECT_TIMEOUT_VARIABLE, LINK_VARIABLE, free_tcp_port
from nearsub.tools.launcher.processes import Processes
from nearsub.tools.launcher.supervision import Launcher
from nearsub.tools.support import registry


def test_two_launches_in_one_process_do_not_inherit_each_others_credentials(tmp_path, runtime_dir, monkeypatch):
    for name in (credentials.VARIABLE, LINK_VARIABLE, CONNECT_TIMEOUT_VARIABLE):
        monkeypatch.delenv(name, raising=False)
    handed: dict[str, list[dict]] = {}  # mission -> the environment of each app started
    spawn = Processes.spawn

    def recording_spawn(self, module, instance, role, extra=()):
        handed.setdefault(self.run_dir.name.split("-")[0], []).append(dict(self.env))
        return spawn(self, module, instance, role, extra)

    monkeypatch.setattr(Processes, "spawn", recording_spawn)
    before = dict(os.environ)
    first = load_mission(ALPHA, ["name=first", "time_limit=2"])
    summary = Launcher(first, None, str(tmp_path / "logs"), quiet=True).run()
    assert summary.outcome == "time_limit", summary.reason
    assert dict(os.environ) == before  # the launcher's own environment is as it was
    own = str(registry.credentials_path("first"))
    assert handed["first"] and all(env[credentials.VARIABLE] == own for env in handed["first"])
    assert not os.path.exists(own)  # removed at the end of the first launch

    # The second mission's router is open (no credentials): its apps must not be handed the first's.
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = subprocess.Popen([sys.executable, "-m", "nearsub", "router", "--listen", endpoint], process_group=0)
    try:
        time.sleep(0.5)
        second = load_mission(ALPHA, ["name=second", "time_limit=2", f'network.connect=["{endpoint}"]'])
        summary = Launcher(second, None, str(tmp_path / "logs"), quiet=True).run()
    finally:
        os.killpg(router.pid, signal.SIGKILL)
        router.wait()
    assert summary.outcome == "time_limit", summary.reason
    assert handed["second"] and all(credentials.VARIABLE not in env for env in handed["second"])
    assert all(env[CONNECT_TIMEOUT_VARIABLE] == f"{second.startup_timeout:g}" for env in handed["second"])
    assert dict(os.environ) == before
