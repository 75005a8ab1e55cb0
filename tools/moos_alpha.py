"""MOOS-IvP's alpha mission beside nearsub's, for `nearsub bench pipeline`.

The MOOS run uses the user's own MOOS-IvP install. Its ivp/missions/s1_alpha files are copied to a
temporary folder and made headless: pMarineViewer and pRealm (which serves the viewer) leave the
Antler block, MOOSTimeWarp is set, and alpha.bhv initialises DEPLOY=true and
MOOS_MANUAL_OVERRIDE=false, the two variables pMarineViewer's DEPLOY button posts. pAntler
launches the community, `uQueryDB --condition=MISSION=complete --wait=T` waits for the endflag of
the mission's return behaviour, and SIGINT to pAntler makes it stop and reap its apps (the
MOOS-IvP documentation, Benjamin et al.: pAntler, uQueryDB, and the helm's initialize and endflag).
The run phase is read from pLogger's alog, whose times are MOOSTime, i.e. wall time times
the warp: from the helm's first IVPHELM_STATE=DRIVE to MISSION=complete.

MOOSDB listens on every interface, so the community runs in a network namespace of its own
(`unshare`): its port is reachable from no other host and clashes with no MOOS community already
running on the machine.

nearsub's alpha runs as `python -m nearsub launch`, as a user types it, so both sides' end-to-end
times include their process start-up; the CPU of each side is that of every process it started
(this process's children, as each reaps its own).
"""

from __future__ import annotations

import json
import math
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from nearsub.common.runtime.processes import stop

# The apps the headless alpha runs, and the one that ends it.
MOOS_APPS = ("pAntler", "MOOSDB", "pLogger", "uSimMarineV22", "pMarinePIDV22", "pHelmIvP", "uProcessWatch",
             "pNodeReporter", "uQueryDB")  # fmt: skip
GUI_APPS = ("pMarineViewer", "pRealm")
MOOS_WARPS = (25.0, 50.0)
START_MARGIN = 120.0  # wall seconds a run may take beyond its simulated time limit at its warp

# Inside the namespace: loopback up, the community, the wait for the end, its stop. The shell
# prints the wall time (epoch seconds) at which uQueryDB saw the end, and exits with its verdict.
COMMUNITY_SCRIPT = """\
ip link set lo up || exit 3
pAntler alpha.moos >antler.out 2>&1 &
antler=$!
uQueryDB alpha.moos --condition=MISSION=complete --wait={limit:g} >query.out 2>&1
found=$?
date +%s.%N
kill -INT "$antler"
wait "$antler"
exit "$found"
"""
NAMESPACE = ("unshare", "--user", "--map-root-user", "--net")


def headless_moos(text: str, warp: float) -> str:
    """alpha.moos without the GUI apps in its Antler block, at MOOSTimeWarp `warp`."""
    lines, warp_set = [], False
    for line in text.splitlines(keepends=True):
        key, _, value = line.partition("=")
        key = key.strip().lower()
        if key == "moostimewarp":
            line, warp_set = f"MOOSTimeWarp = {warp:g}\n", True
        elif key == "run" and value.split("@")[0].strip() in GUI_APPS:
            continue
        lines.append(line)
    if not warp_set:
        raise ValueError("alpha.moos: no MOOSTimeWarp line")
    return "".join(lines)


INITIALIZE_DEPLOY = re.compile(r"^\s*initialize\s+DEPLOY\s*=.*$", re.IGNORECASE | re.MULTILINE)


def headless_bhv(text: str) -> str:
    """alpha.bhv with the vehicle deployed at start (DEPLOY=true, MOOS_MANUAL_OVERRIDE=false)."""
    deployed, count = INITIALIZE_DEPLOY.subn(
        "initialize DEPLOY = true\ninitialize MOOS_MANUAL_OVERRIDE = false", text, count=1
    )
    if not count:
        raise ValueError("alpha.bhv: no 'initialize DEPLOY' line")
    return deployed


def waypoint_legs(bhv_text: str) -> list[list[tuple[float, float]]]:
    """The points of each BHV_Waypoint block of a behaviour file (`polygon` or `points`), in order."""
    legs = []
    for block in re.findall(r"Behavior\s*=\s*BHV_Waypoint\s*\{(.*?)\}", bhv_text, re.DOTALL | re.IGNORECASE):
        spec = re.search(r"^\s*(?:polygon|points)\s*=\s*(\S+)", block, re.MULTILINE | re.IGNORECASE)
        if spec:
            legs.append([tuple(float(v) for v in pair.split(",")) for pair in spec.group(1).split(":")])
    return legs


def start_pose(moos_text: str) -> dict[str, float]:
    """uSimMarineV22's start_pos (x, y, heading, speed) in a .moos file."""
    found = re.search(r"^\s*start_pos\s*=\s*(.+)$", moos_text, re.MULTILINE | re.IGNORECASE)
    if not found:
        return {}
    pairs = (item.split("=") for item in found.group(1).split("//")[0].split(","))
    return {key.strip(): float(value) for key, value in pairs}


def parse_alog(text: str) -> dict:
    """From an alog (`TIME VARIABLE SOURCE VALUE` lines, MOOSTime since the log start): the time of
    the helm's first DRIVE and of MISSION=complete, the last NAV_X/NAV_Y until then and the
    number of PID_STALE posts."""
    drive = end = None
    nav = {"NAV_X": (-math.inf, math.nan), "NAV_Y": (-math.inf, math.nan)}
    stale = 0
    rows = []
    for line in text.splitlines():
        fields = line.split(None, 3)
        if len(fields) < 4 or line.startswith("%"):
            continue
        t, variable, value = float(fields[0]), fields[1], fields[3].strip()
        if variable == "IVPHELM_STATE" and value == "DRIVE":
            drive = t if drive is None else min(drive, t)
        elif variable == "MISSION" and value == "complete":
            end = t if end is None else min(end, t)
        elif variable == "PID_STALE":
            stale += 1
        elif variable in nav:
            rows.append((t, variable, float(value)))
    for t, variable, value in rows:
        if (end is None or t <= end) and t >= nav[variable][0]:
            nav[variable] = (t, value)
    return {"drive": drive, "end": end, "x": nav["NAV_X"][1], "y": nav["NAV_Y"][1], "pid_stale": stale}


def alpha_folder() -> Path | None:
    """ivp/missions/s1_alpha of the MOOS-IvP tree whose bin/ holds the pHelmIvP on PATH."""
    helm = shutil.which("pHelmIvP")
    if helm is None:
        return None
    folder = Path(helm).resolve().parents[1] / "ivp" / "missions" / "s1_alpha"
    return folder if (folder / "alpha.moos").is_file() and (folder / "alpha.bhv").is_file() else None


def skip_reason(folder: Path | None) -> str | None:
    """Why the MOOS run cannot happen here, or None."""
    missing = [app for app in MOOS_APPS if shutil.which(app) is None]
    if missing:
        return f"MOOS-IvP not on PATH (missing {', '.join(missing)})"
    if folder is None:
        return "MOOS-IvP found, but not its ivp/missions/s1_alpha (alpha.moos, alpha.bhv) beside its bin/"
    try:
        namespace = subprocess.run([*NAMESPACE, "sh", "-c", "ip link set lo up"], capture_output=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"cannot run MOOSDB in a network namespace of its own (unshare: {exc})"
    if namespace.returncode:
        text = namespace.stderr.decode(errors="replace").strip().splitlines()
        return f"cannot run MOOSDB in a network namespace of its own (unshare: {text[-1] if text else 'failed'})"
    return None


def children_cpu() -> float:
    """User + system CPU seconds of this process's reaped children (and theirs) so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_timed(argv: list[str], cwd: str, timeout: float) -> tuple[subprocess.CompletedProcess, float, float]:
    """Run `argv` in a process group of its own: its result, wall seconds until it and all it
    started had gone, and their CPU seconds. Past `timeout`, `stop` ends the group."""
    cpu, start = children_cpu(), time.monotonic()
    process = subprocess.Popen(
        argv, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, process_group=0
    )
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        stop([process])
        out, err = process.communicate()
    wall = time.monotonic() - start
    result = subprocess.CompletedProcess(argv, process.returncode, out.decode(errors="replace"),
                                         err.decode(errors="replace"))  # fmt: skip
    return result, wall, children_cpu() - cpu


def run_moos(folder: Path, warp: float, time_limit: float) -> dict:
    """One headless alpha in MOOS-IvP at `warp`, ended by uQueryDB (or after `time_limit` MOOS seconds)."""
    with tempfile.TemporaryDirectory(prefix="nearsub-moos-") as tmp:
        work = Path(tmp)
        (work / "alpha.moos").write_text(headless_moos((folder / "alpha.moos").read_text(), warp))
        (work / "alpha.bhv").write_text(headless_bhv((folder / "alpha.bhv").read_text()))
        script = COMMUNITY_SCRIPT.format(limit=time_limit)
        launched = time.time()
        done, wall, cpu = run_timed([*NAMESPACE, "sh", "-c", script], tmp, time_limit / warp + START_MARGIN)
        logs = sorted(work.glob("**/*.alog"))
        if done.returncode not in (0, 1) or not logs:
            detail = (work / "antler.out").read_text(errors="replace")[-400:] if (work / "antler.out").exists() else ""
            raise RuntimeError(f"MOOS alpha at warp {warp:g}: exit {done.returncode}, no alog. {done.stderr}{detail}")
        alog = parse_alog(logs[0].read_text(errors="replace"))
    seen = done.stdout.split()
    completed = done.returncode == 0 and alog["drive"] is not None and alog["end"] is not None
    run = (alog["end"] - alog["drive"]) / warp if completed else math.nan
    return {
        "outcome": "completed" if completed else "time_limit",
        "wall_s": wall,
        "run_s": run,
        "shutdown_s": launched + wall - float(seen[-1]) if seen else math.nan,
        "cpu_s": cpu,
        "sim_s": alog["end"] - alog["drive"] if completed else math.nan,
        "final": (alog["x"], alog["y"]),
        "pid_stale": alog["pid_stale"],
    }


def run_nearsub(mission_path: Path, warp: float, tag: str, time_limit: float) -> dict:
    """One `nearsub launch` of the mission at `warp`, its final position read from its log."""
    from nearsub.logs import read_messages

    with tempfile.TemporaryDirectory(prefix="nearsub-bench-") as log_dir:
        argv = [sys.executable, "-m", "nearsub", "launch", str(mission_path), "--warp", f"{warp:g}", "--json",
                "--log", log_dir, "--set", f"name=benchvs{tag}"]  # fmt: skip
        done, wall, cpu = run_timed(argv, log_dir, (time_limit / warp if warp else 0.0) + START_MARGIN)
        try:
            summary = json.loads(done.stdout.strip().splitlines()[-1])
        except (IndexError, json.JSONDecodeError):
            detail = done.stderr[-400:]
            raise RuntimeError(
                f"nearsub alpha at warp {warp:g}: no summary (exit {done.returncode}) {detail}"
            ) from None
        final = (math.nan, math.nan)
        for _, _, state in read_messages(summary["log"], f"nearsub/{summary['community']}/*/state"):
            final = (state["x"], state["y"])
    return {
        "outcome": summary["outcome"],
        "wall_s": wall,
        "run_s": summary["run_wall_time"],
        "shutdown_s": summary["shutdown_time"],
        "cpu_s": cpu,
        "sim_s": summary["sim_time"],
        "final": final,
    }


def same_mission(folder: Path, mission) -> list[str]:
    """Where nearsub's mission and MOOS's alpha differ in waypoints or start (empty: they agree)."""
    moos_legs = waypoint_legs((folder / "alpha.bhv").read_text())
    ours = [[tuple(p) for p in leg.points] for leg in mission.apps.helm.legs]
    differences = []
    if moos_legs != ours:
        differences.append(f"waypoints: MOOS {moos_legs}, nearsub {ours}")
    pose = start_pose((folder / "alpha.moos").read_text())
    start = mission.start
    ours_pose = {"x": start.x, "y": start.y, "heading": (90.0 - start.psi_deg) % 360.0}
    if any(not math.isclose(pose.get(k, math.nan), v, abs_tol=1e-9) for k, v in ours_pose.items()):
        differences.append(f"start: MOOS {pose}, nearsub {ours_pose}")
    return differences


def compare(mission_path: Path, repeats: int, verbose: bool) -> dict:
    """nearsub's alpha at warp 25, 50 and 0 and MOOS-IvP's at 25 and 50, `repeats` runs each,
    alternating; {"ran": False, "reason": ...} where MOOS-IvP cannot run here."""
    from nearsub.common.mission.schema import load_mission

    folder = alpha_folder()
    reason = skip_reason(folder)
    if reason:
        return {"ran": False, "reason": f"{reason}: comparison skipped"}
    mission = load_mission(mission_path)
    plan = [(side, warp) for warp in MOOS_WARPS for side in ("nearsub", "moos")] + [("nearsub", 0.0)]
    runs: dict[str, list[dict]] = {f"{side}@{warp:g}": [] for side, warp in plan}
    for index in range(repeats):
        for side, warp in plan:
            try:
                if side == "moos":
                    run = run_moos(folder, warp, mission.time_limit)
                else:
                    run = run_nearsub(mission_path, warp, f"{os.getpid()}_{index}w{warp:g}", mission.time_limit)
            except RuntimeError as exc:
                return {"ran": False, "reason": f"{exc}: comparison stopped"}
            runs[f"{side}@{warp:g}"].append(run)
            if verbose:
                who = "MOOS-IvP" if side == "moos" else side
                print(f"  {who} alpha at warp {warp:g}, run {index + 1}: {run_line(run)}", file=sys.stderr)
    summary = {}
    for name, r in runs.items():
        summary[name] = {
            k: statistics.median(x[k] for x in r) for k in ("wall_s", "run_s", "cpu_s", "shutdown_s", "sim_s")
        }
        summary[name]["final"] = r[-1]["final"]
        summary[name]["outcomes"] = [x["outcome"] for x in r]
        if name.startswith("moos"):
            summary[name]["pid_stale"] = [x["pid_stale"] for x in r]
    ratios = {}
    for warp in MOOS_WARPS:
        ours, theirs = summary[f"nearsub@{warp:g}"], summary[f"moos@{warp:g}"]
        ratios[f"{warp:g}"] = {k: ours[k] / theirs[k] for k in ("wall_s", "run_s", "cpu_s")}
    return {
        "ran": True,
        "repeats": repeats,
        "moos_mission": str(folder),
        "differences": same_mission(folder, mission),
        "runs": summary,
        "ratios_nearsub_over_moos": ratios,
        "nearsub_warp0_over_moos_warp25_wall": summary["nearsub@0"]["wall_s"] / summary["moos@25"]["wall_s"],
    }


def run_line(run: dict) -> str:
    x, y = run["final"]
    line = (
        f"{run['outcome']}, {run['wall_s']:.1f} s end to end, {run['run_s']:.1f} s running, {run['cpu_s']:.1f} CPU-s, "
        f"simulated {run['sim_s']:.1f} s, final ({x:.1f}, {y:.1f})"
    )
    return line + (f", {run['pid_stale']} PID_STALE posts" if "pid_stale" in run else "")


def print_comparison(result: dict) -> None:
    """The side-by-side table, or the one line saying why it was skipped."""
    if not result["ran"]:
        print(f"MOOS-IvP alpha at warp 25 and 50: {result['reason']}")
        return
    print(f"alpha beside MOOS-IvP's ({result['moos_mission']}), medians of {result['repeats']} alternating runs each:")
    print("  side     warp  end to end  running  shutdown   CPU-s  simulated  final x, y (last run)")
    for name, m in result["runs"].items():
        side, warp = name.split("@")
        x, y = m["final"]
        print(
            f"  {'MOOS-IvP' if side == 'moos' else side:<8} {warp:>4}  {m['wall_s']:8.1f} s {m['run_s']:7.1f} s "
            f"{m['shutdown_s']:7.1f} s {m['cpu_s']:7.1f} {m['sim_s']:8.1f} s  {x:6.1f}, {y:6.1f}"
        )
    for warp, r in result["ratios_nearsub_over_moos"].items():
        print(
            f"  nearsub/MOOS at warp {warp}: end to end {r['wall_s']:.2f}, running {r['run_s']:.2f}, "
            f"CPU {r['cpu_s']:.2f}"
        )
    print(
        f"  nearsub at warp 0 end to end / MOOS at warp 25: {result['nearsub_warp0_over_moos_warp25_wall']:.2f} "
        "(target: < 1)"
    )
    for name, m in result["runs"].items():
        if "pid_stale" in m and any(m["pid_stale"]):
            stale = m["pid_stale"]
            print(f"  {name}: pMarinePIDV22 posted PID_STALE {stale} times (its inputs fell behind the warped clock)")
    differences = result["differences"]
    print("  same waypoints and start: " + ("yes" if not differences else "no: " + "; ".join(differences)))
    ours, theirs = result["runs"]["nearsub@0"], result["runs"]["moos@25"]
    gap = math.dist(ours["final"], theirs["final"])
    print(
        f"  they differ in the vehicle (nearsub: the REMUS 100 model; MOOS-IvP: uSimMarineV22's kinematic model): "
        f"simulated {ours['sim_s']:.1f} s against {theirs['sim_s']:.1f} s at warp 25, "
        f"final positions (last runs) {gap:.1f} m apart"
    )
