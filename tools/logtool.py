"""`nearsub log`: inspect and export mission logs (MCAP)."""

from __future__ import annotations

import csv
import json
import sys
from collections import Counter, defaultdict
from pathlib import Path

from nearsub.common.runtime.logfile import INVALID_SUFFIX, LogContents, read_log


def flatten(value: dict) -> dict:
    """{'a': 1, 'd': {'x': 2}} -> {'a': 1, 'd.x': 2}."""
    out = {}
    for key, item in value.items():
        if isinstance(item, dict):
            for sub, v in flatten(item).items():
                out[f"{key}.{sub}"] = v
        else:
            out[key] = item
    return out


def _select(contents: LogContents, topic: str | None):
    for record in contents.records:
        if topic is None or _matches(topic, record.topic):
            yield record


def _matches(pattern: str, topic: str) -> bool:
    """Key-expression match with * (one chunk) and ** (any chunks)."""
    p, t = pattern.split("/"), topic.split("/")

    def walk(i: int, j: int) -> bool:
        if i == len(p):
            return j == len(t)
        if p[i] == "**":
            return any(walk(i + 1, k) for k in range(j, len(t) + 1))
        if j < len(t) and (p[i] == "*" or p[i] == t[j]):
            return walk(i + 1, j + 1)
        return False

    return walk(0, 0)


def info_command(args) -> int:
    contents = read_log(args.log)
    counts = Counter(r.topic for r in contents.records)
    spans = defaultdict(list)
    for r in contents.records:
        spans[r.topic].append(r.sim_time)
    outcome = contents.metadata.get("outcome", {})
    summary = {
        "file": str(args.log),
        "recovered": contents.recovered,
        "messages": len(contents.records),
        "sim_start": min((r.sim_time for r in contents.records), default=0.0),
        "sim_end": max((r.sim_time for r in contents.records), default=0.0),
        "outcome": outcome,
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
    if args.json:
        print(json.dumps(summary))
        return 0
    print(f"log      {summary['file']}" + ("  (recovered: the file was not finished)" if contents.recovered else ""))
    print(f"messages {summary['messages']}, simulated {summary['sim_start']:.2f} .. {summary['sim_end']:.2f} s")
    if outcome:
        print(f"outcome  {outcome.get('outcome')} after {outcome.get('steps')} steps: {outcome.get('reason', '')}")
    print(f"{'topic':<50} {'count':>8} {'Hz (sim)':>9}")
    for topic, item in summary["topics"].items():
        print(f"{topic:<50} {item['count']:>8} {item['hz']:>9.2f}")
    return 0


def export_command(args) -> int:
    contents = read_log(args.log)
    records = list(_select(contents, args.topic))
    out = open(args.output, "w", newline="") if args.output and args.format != "csv" else sys.stdout
    try:
        if args.format == "json":
            for r in records:
                out.write(json.dumps({"topic": r.topic, "t": r.sim_time, "value": r.value()}) + "\n")
        elif args.format == "alog":
            _write_alog(records, contents, out)
        else:
            return _write_csv(records, args.output)
    finally:
        if out is not sys.stdout:
            out.close()
    return 0


def _write_alog(records, contents: LogContents, out) -> None:
    """MOOS alog: a %% header, then `time VARIABLE SOURCE VALUE` per message (moos-notes.md 7)."""
    mission = contents.metadata.get("mission", {}).get("name", "")
    out.write(f"%% LOG FILE:       nearsub mission {mission}\n%% LOGSTART        0.0\n")
    for r in records:
        value = r.value()
        variable = "_".join(r.topic.split("/")[2:]).replace(INVALID_SUFFIX, "_INVALID").upper()
        source = value.get("source", "?") if isinstance(value, dict) else "?"
        fields = flatten(value) if isinstance(value, dict) else {"raw": value}
        text = ",".join(f"{k}={v}" for k, v in fields.items() if k not in ("schema_version", "source"))
        out.write(f"{r.sim_time:.5f} {variable} {source} {text}\n")


def _write_csv(records, output: str | None) -> int:
    by_topic = defaultdict(list)
    for r in records:
        if not r.topic.endswith(INVALID_SUFFIX):
            by_topic[r.topic].append(flatten(r.value()))
    if not by_topic:
        print("nearsub log export: no messages match", file=sys.stderr)
        return 1
    if output is None and len(by_topic) > 1:
        print(
            "nearsub log export: several topics match; pass --topic KEY or -o DIR for one CSV per topic",
            file=sys.stderr,
        )
        return 2
    for topic, rows in by_topic.items():
        columns = list(dict.fromkeys(c for row in rows for c in row))
        if output is None:
            target = sys.stdout
        else:
            Path(output).mkdir(parents=True, exist_ok=True)
            target = open(Path(output) / (topic.replace("/", "_") + ".csv"), "w", newline="")
        writer = csv.DictWriter(target, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
        if target is not sys.stdout:
            target.close()
    return 0
