"""Shared fixtures. Multi-process tests get an isolated runtime folder, a unique community name
and a teardown that kills every process group they started."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from nearsub.common.runtime.processes import single_blas_thread, stop

# One BLAS thread, as the `nearsub` command sets for itself and what it starts, before anything
# imports numpy (nothing above does): results that pass through a dense solve then agree to the
# last bit between the tests and the processes they start.
single_blas_thread()
ROOT = Path(__file__).resolve().parents[1]
ALPHA = ROOT / "missions" / "alpha.toml"


@pytest.fixture
def runtime_dir(tmp_path, monkeypatch):
    path = tmp_path / "runtime"
    path.mkdir()
    monkeypatch.setenv("NEARSUB_RUNTIME_DIR", str(path))
    return path


@pytest.fixture
def community():
    return f"t{uuid.uuid4().hex[:10]}"


class Launches:
    """Starts `nearsub launch` subprocesses and kills them (and their children) at teardown."""

    def __init__(self, log_dir: Path):
        self.log_dir = log_dir
        self.processes: list[subprocess.Popen] = []

    def start(self, mission: Path, *args: str) -> subprocess.Popen:
        argv = [sys.executable, "-m", "nearsub", "launch", str(mission), "--log", str(self.log_dir), "--json", *args]
        process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, process_group=0)
        self.processes.append(process)
        return process

    def run(self, mission: Path, *args: str, timeout: float = 90.0) -> tuple[int, dict, str]:
        import json

        process = self.start(mission, *args)
        out, err = process.communicate(timeout=timeout)
        summary = json.loads(out.strip().splitlines()[-1]) if out.strip() else {}
        return process.returncode, summary, err

    def kill_all(self) -> None:
        stop(self.processes, ladder=(signal.SIGKILL,))
        # Apps run in their own process groups; they die with the launcher (PDEATHSIG), but make
        # sure: any process still running our modules under this log folder is killed.
        time.sleep(0.2)
        out = subprocess.run(["pgrep", "-f", str(self.log_dir)], capture_output=True, text=True).stdout
        for pid in out.split():
            try:
                os.kill(int(pid), signal.SIGKILL)
            except ProcessLookupError:
                pass


@pytest.fixture
def launches(tmp_path, runtime_dir):
    handle = Launches(tmp_path / "logs")
    yield handle
    handle.kill_all()


def nearsub(*args: str, timeout: float = 60.0, env=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "nearsub", *args], capture_output=True, text=True, timeout=timeout, env=env
    )
