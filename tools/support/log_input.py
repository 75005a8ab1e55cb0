"""The mission logs a command is given (`log`, `log play`, `view`, `foxglove`): paths checked to be
MCAP logs, the records of `--topic` and `--vehicle`, the mission a log holds. Bad input is one
line (InputError)."""

from __future__ import annotations

import glob
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import InputError
from .topics import topic_key

if TYPE_CHECKING:
    from nearsub.common.runtime.logfile import LogContents


MCAP_MAGIC = b"\x89MCAP0\r\n"  # the first 8 bytes of every MCAP file (MCAP specification, "Magic")


class LogInputError(InputError):
    """A path that is not a readable MCAP log; the one-line text names it."""


def log_paths(patterns: list[str]) -> list[Path]:
    """The files named, a pattern with wildcards standing for the files it matches, each checked
    to exist and to start as an MCAP file does."""
    paths: list[Path] = []
    for pattern in patterns:
        if not Path(pattern).exists() and glob.has_magic(pattern):
            matched = sorted(glob.glob(pattern))
            if not matched:
                raise LogInputError(f"{pattern}: no file matches")
            paths += [Path(m) for m in matched]
        else:
            paths.append(Path(pattern))
    for path in paths:
        check_log(path)
    return paths


def check_log(path: Path) -> None:
    """A LogInputError unless `path` is a readable file that starts as an MCAP file does."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
    except FileNotFoundError:
        raise LogInputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise LogInputError(f"{path}: is a folder, not a log file") from None
    except OSError as exc:
        raise LogInputError(f"{path}: cannot read ({exc.strerror})") from None
    if head != MCAP_MAGIC:
        raise LogInputError(f"{path}: not an MCAP log (it does not start with the MCAP magic bytes)")


def select_topic(contents: LogContents, topic: str | None):
    """The records of `--topic` (every record without one)."""
    wanted = topic_filter(topic)
    for record in contents.records:
        if wanted(record.topic):
            yield record


def vehicle_records(contents: LogContents, args, records=None, error=InputError) -> list:
    """The records of `--vehicle` (`LogContents.vehicle_records`); a vehicle the log does not
    have is bad input (`error`), naming the ones it has."""
    if args.vehicle not in contents.vehicles():
        known = ", ".join(contents.vehicles()) or "none"
        raise error(f"--vehicle {args.vehicle}: not a vehicle of {args.log} (its vehicles: {known})")
    return contents.vehicle_records(args.vehicle, records)


def topic_filter(pattern: str | None):
    """`nearsub.logs.topic_filter` for a `--topic` option (a key expression or a short key such
    as `state`, `topics.topic_key`): a bad pattern is bad input."""
    from nearsub.logs import topic_filter as logs_topic_filter

    try:
        return logs_topic_filter(None if pattern is None else topic_key(pattern, option="--topic"), "--topic")
    except ValueError as exc:
        raise InputError(str(exc)) from None


def is_log(target: str) -> bool:
    """Whether `nearsub view MISSION` names a log (else a running mission, or its mission file)."""
    return target.endswith(".mcap") or (Path(target).is_file() and Path(target).suffix != ".toml")


def mission_of_log(path: Path):
    """The resolved mission stored in a log's metadata, or None."""
    import json

    from nearsub.common.mission.schema import mission_from_dict
    from nearsub.common.runtime.logfile import read_log

    resolved = read_log(path).metadata.get("mission", {}).get("resolved")
    return mission_from_dict(json.loads(resolved), f"{path} metadata") if resolved else None
