"""Screenshots of `nearsub view` for docs/viewer: a live overtake near the submarine's stern, the
replay of its log at the collision, the replay of one envelope cell (its mission written by
`nearsub envelope --cell-mission`), the replay of a log of two vehicles, and launch_two (two UUVs
beside the submarine) replayed at its middle (`--fleet` makes only those two). Run from the
repository: `.venv/bin/python tests/viewer_shots.py [--fleet]`.

The mission pauses itself just before the collision (pause_at_step), so the live picture is the
same on every run; the page's Resume button then lets it finish and the log is replayed.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from browser import Browser

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "missions" / "overtake_stern_standard.toml"
PAUSE_STEP = 1915  # t = 95.75 s, 4.5 s before the collision with standard waypoints (t = 100.25 s)
# The envelope cell: the SDV of figure 5-10 with the standard helm, starting beside the afterbody.
CELL = ("--vehicle", "sdv", "--behaviour", "waypoints", "--cell-mission=-0.3,0.065")


def nearsub(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "nearsub", *args], stdout=subprocess.PIPE, text=True, process_group=0
    )


def url_of(process: subprocess.Popen) -> str:
    line = process.stdout.readline()
    if not line.startswith("nearsub view: "):
        raise RuntimeError(f"nearsub view printed {line!r}")
    return line.split(": ", 1)[1].split()[0]  # the control URL


def clock_paused(community: str) -> bool:
    done = subprocess.run(
        [sys.executable, "-m", "nearsub", "clock", community, "status"], capture_output=True, text=True
    )
    return done.returncode == 0 and json.loads(done.stdout)["paused"]


def replay_shot(browser: Browser, log: str, path: Path, viewers: list) -> None:
    """Open the replay of `log`, scrub to its last state and capture it."""
    replay = nearsub("view", log)
    viewers.append(replay)
    browser.open(url_of(replay))
    browser.wait_for("window.nearsub.drawn", 30)
    t = browser.evaluate("window.nearsub.scene.range[1]")
    browser.evaluate(f"{{ const s = document.getElementById('scrub'); s.value = {t}; s.oninput(); }}")
    browser.wait_for(f"window.nearsub.drawn.t >= {t} - 1e-6", 30)  # t is a float from the page
    time.sleep(0.3)
    print(browser.screenshot(path))


def envelope_cell_log(work: Path) -> str:
    """Write the envelope cell's mission, fly it through the launcher, return its log."""
    cell = work / "cell.toml"
    subprocess.run([sys.executable, "-m", "nearsub", "envelope", *CELL, "-o", str(cell)], check=True)
    done = subprocess.run(
        [sys.executable, "-m", "nearsub", "launch", str(cell), "--json", "--log", str(work / "logs")],
        capture_output=True,
        text=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])["log"]


def fleet_shot(out: Path, work: Path) -> None:
    """The replay of the two-vehicle log of the tests (`logsample.write_fleet_log`: alpha flown by
    "alfa" and, 30 m to its side, by "bravo", whose log stops half-way) at its end, 120 s."""
    from logsample import write_fleet_log

    log = work / "fleet.mcap"
    write_fleet_log(log, seconds=120.0)
    viewers = []
    try:
        with Browser(width=1400, height=800) as browser:
            replay_shot(browser, str(log), out / "replay-fleet.png", viewers)
    finally:
        for process in viewers:
            os.killpg(process.pid, signal.SIGTERM)
            process.wait(timeout=30)


def fleet_submarine_shot(out: Path, work: Path) -> None:
    """launch_two (two UUVs departing from beside the submarine) flown through the launcher and
    replayed at the middle of its log, opened there with `?t=` and auv2 selected."""
    done = subprocess.run(
        [sys.executable, "-m", "nearsub", "launch", "launch_two", "--json", "--log", str(work / "logs")],
        capture_output=True,
        text=True,
        check=True,
    )
    log = json.loads(done.stdout.strip().splitlines()[-1])["log"]
    replay = nearsub("view", log)
    try:
        with Browser(width=1400, height=800) as browser:
            browser.open(url_of(replay))
            browser.wait_for("window.nearsub.drawn", 30)
            middle = sum(browser.evaluate("window.nearsub.scene.range")) / 2
            browser.open(f"{url_of_page(browser)}?t={middle:.2f}")
            browser.wait_for(f"window.nearsub.drawn && Math.abs(window.nearsub.drawn.t - {middle:.2f}) < 0.06", 30)
            browser.evaluate("{ const v = document.getElementById('vehicle'); v.value = 'auv2'; v.onchange(); }")
            time.sleep(0.3)
            print(browser.screenshot(out / "replay-fleet-submarine.png"))
    finally:
        os.killpg(replay.pid, signal.SIGTERM)
        replay.wait(timeout=30)


def url_of_page(browser: Browser) -> str:
    return browser.evaluate("window.location.origin + window.location.pathname")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "viewer"))
    parser.add_argument("--fleet", action="store_true", help="only the replay of two vehicles")
    args = parser.parse_args()
    out = Path(args.out)
    work = Path(tempfile.mkdtemp(prefix="nearsub-shots-"))
    os.environ["NEARSUB_RUNTIME_DIR"] = str(work / "runtime")
    sys.path.insert(0, str(ROOT / "tests"))
    if args.fleet:
        fleet_shot(out, work)
        fleet_submarine_shot(out, work)
        return 0
    launch = subprocess.Popen(
        [sys.executable, "-m", "nearsub", "launch", str(MISSION), "--warp", "0", "--json"]
        + ["--set", f"pause_at_step={PAUSE_STEP}", "--log", str(work / "logs")],
        stdout=subprocess.PIPE,
        text=True,
        process_group=0,
    )
    viewers = []
    try:
        from helpers import wait_registered

        wait_registered("overtake_stern_standard", timeout=300)
        # Follow from the start: a viewer that joins a paused mission sees only what the log has
        # flushed so far (whole chunks) until the mission moves again.
        live = nearsub("view", "overtake_stern_standard")
        viewers.append(live)
        while not clock_paused("overtake_stern_standard"):
            if launch.poll() is not None:
                raise RuntimeError("the mission ended before it paused")
            time.sleep(0.5)
        with Browser(width=1400, height=800) as browser:
            browser.open(url_of(live))
            browser.wait_for(f"window.nearsub.drawn && window.nearsub.drawn.step >= {PAUSE_STEP - 5}", 30)
            browser.wait_for("document.getElementById('st-state').textContent === 'paused'", 30)
            print(browser.screenshot(out / "live-overtake.png"))
            browser.evaluate("document.getElementById('follow').click()")
            time.sleep(0.5)
            print(browser.screenshot(out / "live-overtake-follow.png"))
            browser.evaluate("document.getElementById('resume').click()")
        summary = json.loads(launch.communicate(timeout=120)[0].strip().splitlines()[-1])
        with Browser(width=1400, height=800) as browser:
            replay_shot(browser, summary["log"], out / "replay-overtake.png", viewers)  # the collision
            browser.evaluate("document.getElementById('follow').click()")
            time.sleep(0.5)
            print(browser.screenshot(out / "replay-overtake-follow.png"))
        cell_log = envelope_cell_log(work)
        with Browser(width=1400, height=800) as browser:
            replay_shot(browser, cell_log, out / "replay-envelope-cell.png", viewers)
            browser.evaluate("document.getElementById('follow').click()")
            time.sleep(0.5)
            print(browser.screenshot(out / "replay-envelope-cell-follow.png"))
        fleet_shot(out, work)
        fleet_submarine_shot(out, work)
    finally:
        for process in [launch, *viewers]:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGTERM)
                process.wait(timeout=30)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
