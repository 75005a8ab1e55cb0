"""Every app has one entry (apps/entry.py): a run file it cannot read is one line naming the app
and the file, exit 2, no traceback, whichever app it is."""

from __future__ import annotations

import subprocess
import sys

import pytest

APPS = {
    "helm": ["--instance", "helm-1"],
    "pid": ["--instance", "pid-1"],
    "sim": ["--instance", "sim-1"],
    "clock": [],
    "logger": ["--output", "unused.mcap"],
    "surrogate": [],
}


@pytest.mark.parametrize("app", sorted(APPS))
def test_a_run_file_that_cannot_be_read_is_one_line_and_exit_2(app, tmp_path):
    missing = tmp_path / "run.json"
    done = subprocess.run(
        [sys.executable, "-m", f"nearsub.apps.{app}", "--run", str(missing), *APPS[app]],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=60,
    )
    instance = APPS[app][1] if APPS[app][:1] == ["--instance"] else app
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith(f"[{instance}] cannot read {missing}: ") and done.stderr.count("\n") == 1, done.stderr
    assert not (tmp_path / "unused.mcap").exists()
