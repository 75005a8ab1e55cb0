"""`nearsub log info|export|plot`: inspect, export and draw mission logs (MCAP)."""

from __future__ import annotations

import csv
import json
import sys
from collections import Counter, defaultdict
from pathlib import Path

from ..support.errors import InputError
from ..support.log_input import check_log, log_paths, select_topic, vehicle_records
from ..support.outputs import output_file, output_folder


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("log")
    lg = p.add_subparsers(dest="log_command", required=True)
    t = lg.add_parser("info", help="topics, counts, rates and outcome of one or more logs")
    t.add_argument("log", nargs="+", help="MCAP files (a quoted glob is expanded too)")
    t.add_argument("--json", action="store_true")
    t.set_defaults(func=info_command)
    t = lg.add_parser(
        "export", help="export as csv, json lines, a MOOS alog (alogview, aloggrep) or an MCAP for Foxglove"
    )
    t.add_argument("log")
    t.add_argument("--format", choices=("csv", "json", "alog", "foxglove"), default="json")
    t.add_argument("--topic", help="key expression to select (wildcards allowed), or a short key such as state")
    t.add_argument(
        "--vehicle",
        metavar="NAME",
        help="one vehicle's topics and the mission-wide ones (alog: that vehicle's own alog)",
    )
    t.add_argument(
        "-o",
        "--output",
        help="output file (json, alog, foxglove; default stdout, foxglove LOG-foxglove.mcap here); csv: FILE.csv "
        "for one topic, any other name a folder of one TOPIC.csv per topic (default stdout, one topic)",
    )
    t.set_defaults(func=export_command)
    t = lg.add_parser("play", help="republish a log onto the bus (uPlayBack, ros2 bag play)")
    from ..logplay import add_arguments, play_command

    add_arguments(t)
    t.set_defaults(func=play_command)
    t = lg.add_parser("plot", help="trajectory in the submarine frame and time series (PNG)")
    t.add_argument("log")
    t.add_argument("-o", "--output", help="PNG file (default: LOG.png, next to the log; .png added to a bare name)")
    t.add_argument("--title")
    t.set_defaults(func=plot_command)


def info_command(args) -> int:
    paths = log_paths(args.log)
    for i, path in enumerate(paths):
        summary = log_summary(path)
        lines = summary.pop("approach_lines")
        if args.json:
            print(json.dumps(summary))  # one JSON object per line and log
        else:
            if i:
                print()
            print_summary(summary, lines)
    return 0


def log_summary(path: Path) -> dict:
    from nearsub.common.analysis.approach import log_approaches
    from nearsub.common.runtime.logfile import read_log

    contents = read_log(path)
    approaches = log_approaches(contents)
    counts = Counter(r.topic for r in contents.records)
    spans = defaultdict(list)
    for r in contents.records:
        spans[r.topic].append(r.sim_time)
    return {
        "file": str(path),
        "recovered": contents.recovered,
        "damage": contents.damage,
        "messages": len(contents.records),
        "sim_start": min((r.sim_time for r in contents.records), default=0.0),
        "sim_end": max((r.sim_time for r in contents.records), default=0.0),
        "outcome": contents.metadata.get("outcome", {}),
        "invalid_dropped": {key: int(n) for key, n in contents.metadata.get("invalid_dropped", {}).items()},
        "vehicles": contents.vehicles(),
        "approaches": approaches.as_dict() if approaches else None,
        "approach_lines": approaches.lines() if approaches else [],
        "topics": {
            topic: {
                "count": n,
                "hz": (n - 1) / (max(spans[topic]) - min(spans[topic]))
                if n > 1 and max(spans[topic]) > min(spans[topic])
                else 0.0,
            }
            for topic, n in sorted(counts.items())
        },
    }


def print_summary(summary: dict, approach_lines: list[str]) -> None:
    """The summary as a rich table: plain text when piped, wrapped to the terminal's width."""
    from rich.table import Table

    from nearsub.common.runtime.messages import model_for_key

    from ..support import tables

    outcome = summary["outcome"]
    recovered = f"  (recovered: {summary['damage']})" if summary["recovered"] else ""
    caption = f"{summary['messages']} messages, simulated {summary['sim_start']:.2f} .. {summary['sim_end']:.2f} s"
    if outcome:
        caption += f"; {outcome.get('outcome')} after {outcome.get('steps')} steps: {outcome.get('reason', '')}"
    for key, count in summary["invalid_dropped"].items():  # a flood the logger counted but did not keep
        caption += f"; {count} more invalid messages on {key} counted, not kept"
    table = Table(title=f"{summary['file']}{recovered}", caption=caption, title_justify="left", caption_justify="left")
    for name in ("topic", "message"):
        table.add_column(name)
    for name in ("count", "Hz (simulated)"):
        table.add_column(name, justify="right")
    for topic, item in summary["topics"].items():
        model = model_for_key(topic)
        table.add_row(topic, model.__name__ if model else "", str(item["count"]), f"{item['hz']:.2f}")
    console = tables.console()
    console.print(table)
    vehicles = Table("vehicle", title="vehicles", title_justify="left")
    for name in ("states", "steps", "simulated time (s)"):
        vehicles.add_column(name, justify="right")
    for name, item in summary["vehicles"].items():
        if item["states"]:
            steps = f"{item['first_step']} .. {item['last_step']}"
            span = f"{item['t_start']:.2f} .. {item['t_end']:.2f}"
        else:
            steps = span = "-"
        vehicles.add_row(name, str(item["states"]), steps, span)
    console.print(vehicles)
    for line in approach_lines:
        console.print(line, highlight=False)


def export_command(args) -> int:
    from nearsub.common.runtime.logfile import read_log

    check_log(Path(args.log))
    if args.format == "foxglove":
        return _export_foxglove(args)
    output = _export_output(args)
    contents = read_log(args.log)
    records = list(select_topic(contents, args.topic))
    if args.vehicle is not None:
        records = vehicle_records(contents, args, records)
    if args.format == "csv":
        return _write_csv(records, output, args.topic)
    if not records:
        raise _no_match(args.topic)
    out = open(output, "w", newline="") if output else sys.stdout
    try:
        if args.format == "json":
            for r in records:
                out.write(json.dumps({"topic": r.topic, "t": r.sim_time, "value": r.value()}) + "\n")
        else:
            from nearsub.common.physics.vehicles import get_vehicle
            from nearsub.common.runtime.alog import write_alog

            write_alog(contents, out, get_vehicle, records, args.vehicle)
    finally:
        if out is not sys.stdout:
            out.close()
    return 0


def _export_output(args) -> Path | None:
    """The checked -o of an export: a file, or a folder for csv unless it is named *.csv; the
    default of foxglove is beside the working directory. Never the log itself."""
    if args.format == "foxglove":
        args.output = args.output or f"{Path(args.log).stem}-foxglove.mcap"
    if args.output is None:
        return None
    if args.format == "csv" and Path(args.output).suffix.lower() != ".csv":
        return output_folder(args.output)
    return output_file(args.output, source=args.log, source_is="the log being exported")


def _no_match(topic: str | None) -> InputError:
    return InputError(f"--topic {topic}: no messages match" if topic else "the log has no messages to export")


def _export_foxglove(args) -> int:
    """An MCAP that Foxglove opens as is (tools/commands/foxglove.py); by default beside cwd, never over the log."""
    from .foxglove import export_foxglove

    if args.topic or args.vehicle:
        option = "--topic" if args.topic else "--vehicle"
        raise InputError(f"{option}: the Foxglove export keeps every topic (the scene needs the states and events)")
    output = _export_output(args)
    from nearsub.common.mission.schema import MissionError

    try:
        count = export_foxglove(args.log, output)
    except MissionError as exc:  # a mission this version cannot read: one line, as `nearsub view` says it
        raise InputError(str(exc)) from None
    print(f"{output}: {count} messages", file=sys.stderr)
    return 0


def _write_csv(records, output: Path | None, topic: str | None) -> int:
    """One CSV per topic: on stdout or into -o FILE.csv for one topic, else into the folder -o."""
    from nearsub.common.runtime.logfile import INVALID_SUFFIX
    from nearsub.logs import flatten

    by_topic = defaultdict(list)
    for r in records:
        if not r.topic.endswith(INVALID_SUFFIX):
            by_topic[r.topic].append(flatten(r.value()))
    if not by_topic:
        raise _no_match(topic)
    one_file = output is None or output.suffix.lower() == ".csv"
    if one_file and len(by_topic) > 1:
        where = "" if output is None else f"-o {output}: "
        raise InputError(f"{where}{len(by_topic)} topics match; pass --topic KEY, or -o DIR for one CSV per topic")
    if not one_file:
        output.mkdir(parents=True, exist_ok=True)
    for name, rows in by_topic.items():
        columns = list(dict.fromkeys(c for row in rows for c in row))
        if output is None:
            target = sys.stdout
        else:
            target = open(output if one_file else output / (name.replace("/", "_") + ".csv"), "w", newline="")
        writer = csv.DictWriter(target, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
        if target is not sys.stdout:
            target.close()
    return 0


def plot_command(args) -> int:
    check_log(Path(args.log))
    output = Path(args.output) if args.output else Path(args.log).with_suffix(".png")
    if not output.suffix and not output.is_dir():  # matplotlib would add .png itself: name the file it writes
        output = output.with_suffix(".png")
    output_file(output, source=args.log, source_is="the log being plotted")
    from matplotlib.backend_bases import FigureCanvasBase

    if output.suffix[1:].lower() not in FigureCanvasBase.get_supported_filetypes():
        raise InputError(f"-o {output}: not an image type matplotlib writes (give NAME.png)")
    from ..plot import plot_log

    try:
        out = plot_log(args.log, output, args.title)
    except ValueError as exc:  # the log holds nothing to plot: bad input, as for `view`
        raise InputError(str(exc)) from None
    except OSError as exc:
        print(f"nearsub log plot: {exc}", file=sys.stderr)
        return 1
    print(out)
    return 0
