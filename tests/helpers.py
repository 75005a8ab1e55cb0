"""Reading logs back for comparisons."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

from nearsub.common.logfile import read_log


def log_path(summary: dict) -> Path:
    return Path(summary["log"])


def per_topic(path: Path, skip=("/events/launcher", "/status/", "/control/", "/reply/")) -> dict[str, list[bytes]]:
    """Payload bytes of each topic in arrival order, leaving out wall-clock-dependent topics."""
    topics = defaultdict(list)
    for record in read_log(path).records:
        if not any(part in record.topic for part in skip):
            topics[record.topic.split("/", 2)[2]].append(record.data)
    return dict(topics)
