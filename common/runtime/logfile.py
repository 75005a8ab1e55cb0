"""Mission logs: MCAP files holding the msgpack bytes exactly as received (docs/design.md,
"Transport").

One channel per key expression, `message_encoding = "msgpack"`, schema = the pydantic model's
JSON schema; `log_time` is simulated time in ns (for a control request, the simulated time the
mission had reached when it arrived), `publish_time` the wall-clock receive time. The
mission (resolved, as JSON) is stored as metadata and the mission file as an attachment.

Chunks are small, so a log cut short by a crash loses at most its last chunk, and a damaged byte
at most its chunk: `read_log` then keeps every intact chunk (`LogContents.damage` says what).
"""

from __future__ import annotations

import io
import json
import shutil
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import msgpack
from mcap.exceptions import EndOfFile
from mcap.reader import SeekingReader, make_reader
from mcap.records import Channel, Metadata
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from nearsub.common.runtime.keys import vehicle_of
from nearsub.common.runtime.messages import model_for_key

CHUNK_SIZE = 64 * 1024
INVALID_SUFFIX = "#invalid"
# A logged step of one vehicle, compressed: 184 kB for the 1200 steps of missions/alpha.toml
# (measured, nearsub 2026-12); a launch wants room for twice that rate, a busier mission logs more.
BYTES_PER_VEHICLE_STEP = 160


def room_needed(steps: int, vehicles: int) -> int:
    """Bytes a log needs for its first `steps` steps of `vehicles` vehicles: twice the measured
    rate, plus the header, the mission file and a few chunks in flight."""
    return 2 * BYTES_PER_VEHICLE_STEP * steps * vehicles + 4 * CHUNK_SIZE


def no_space_left(folder: str | Path) -> bool:
    """Whether the file system of `folder` has less room than one chunk: a logger there fails
    at its next chunk (ENOSPC), and says so only in its output file, on the same full disk."""
    try:
        return shutil.disk_usage(folder).free < CHUNK_SIZE
    except OSError:
        return False


class LogWriter:
    """Append messages to an MCAP file; always call `finish` (it writes the index)."""

    def __init__(self, path: str | Path, library: str = "nearsub"):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        self._writer = Writer(self._file, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library=library)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[int, int] = {}
        self.count = 0
        self.finished = False

    def _channel(self, key: str, valid: bool) -> int:
        topic = key if valid else key + INVALID_SUFFIX
        channel = self._channels.get(topic)
        if channel is not None:
            return channel
        schema_id = 0
        model = model_for_key(key) if valid else None
        if model is not None:
            schema_id = self._schemas.get(model.__name__, 0)
            if not schema_id:
                schema_id = self._writer.register_schema(
                    name=f"nearsub.{model.__name__}",
                    encoding="jsonschema",
                    data=json.dumps(model.model_json_schema()).encode(),
                )
                self._schemas[model.__name__] = schema_id
        encoding = "msgpack" if valid else "application/octet-stream"
        channel = self._writer.register_channel(topic=topic, message_encoding=encoding, schema_id=schema_id)
        self._channels[topic] = channel
        return channel

    def write(self, key: str, data: bytes, sim_time: float, valid: bool = True) -> None:
        channel = self._channel(key, valid)
        sequence = self._sequence.get(channel, 0)
        self._sequence[channel] = sequence + 1
        self._writer.add_message(
            channel_id=channel,
            log_time=max(0, int(round(sim_time * 1e9))),
            data=data,
            publish_time=time.time_ns(),
            sequence=sequence,
        )
        self.count += 1

    def metadata(self, name: str, values: dict[str, str]) -> None:
        self._writer.add_metadata(name, {k: str(v) for k, v in values.items()})

    def attach(self, name: str, data: bytes, media_type: str = "text/plain") -> None:
        now = time.time_ns()
        self._writer.add_attachment(create_time=now, log_time=0, name=name, media_type=media_type, data=data)

    def finish(self) -> None:
        if not self.finished:
            self.finished = True
            self._writer.finish()
            self._file.close()


@dataclass
class LogRecord:
    topic: str
    log_time: int
    publish_time: int
    sequence: int
    data: bytes

    @property
    def sim_time(self) -> float:
        return self.log_time / 1e9

    def value(self) -> dict:
        """The decoded msgpack map (raw bytes for invalid payloads)."""
        if self.topic.endswith(INVALID_SUFFIX):
            return {"raw": self.data.hex()}
        return msgpack.unpackb(self.data)


@dataclass
class LogContents:
    records: list[LogRecord]
    metadata: dict[str, dict[str, str]]
    recovered: bool  # True when the file could not be read in one piece (`damage` says why)
    damage: str = ""  # what was wrong and what was kept, for a user; "" for an intact file

    def topics(self) -> list[str]:
        return sorted({r.topic for r in self.records})

    def vehicle_records(self, vehicle: str, records: Iterable[LogRecord] | None = None) -> list[LogRecord]:
        """One vehicle's part of the log (of `records`, default all), as that vehicle's pLogger
        would write it in a MOOS-IvP fleet: its own records and the mission-wide ones (clock,
        mission events, control requests)."""
        records = self.records if records is None else records
        owners = ((r, vehicle_of(r.topic.removesuffix(INVALID_SUFFIX))) for r in records)
        return [r for r, owner in owners if owner is None or owner[0] == vehicle]

    def vehicles(self) -> dict[str, dict]:
        """The vehicles named by the log's keys (nearsub/<c>/<vehicle>/...), sorted by name, each
        with its states' count, first and last step and simulated time span (None without states)."""
        found: dict[str, dict] = {}
        for r in self.records:
            owner = vehicle_of(r.topic.removesuffix(INVALID_SUFFIX))
            if owner is None:
                continue
            item = found.setdefault(
                owner[0], {"states": 0, "first_step": None, "last_step": None, "t_start": None, "t_end": None}
            )
            if owner[1] != "state" or r.topic.endswith(INVALID_SUFFIX):
                continue
            step = r.value().get("step")
            item["states"] += 1
            item["first_step"] = step if item["first_step"] is None else min(item["first_step"], step)
            item["last_step"] = step if item["last_step"] is None else max(item["last_step"], step)
            item["t_start"] = r.sim_time if item["t_start"] is None else min(item["t_start"], r.sim_time)
            item["t_end"] = r.sim_time if item["t_end"] is None else max(item["t_end"], r.sim_time)
        return dict(sorted(found.items()))


def vehicle_spec(resolved: dict | None, name: str):
    """What a resolved mission (its JSON, as a dict) says the vehicle named `name` in the keys is:
    its `[[vehicles]]` entry's type, else the mission's `vehicle` (a library name or the vehicle
    in full); None without a mission."""
    if not isinstance(resolved, dict):
        return None
    for entry in resolved.get("vehicles") or []:
        if isinstance(entry, dict) and entry.get("name") == name and entry.get("type"):
            return entry["type"]
    return resolved.get("vehicle")


def read_log(path: str | Path, topics: Iterable[str] | None = None) -> LogContents:
    """Every message of a log (or of the given `topics` only) in file order, with its metadata. A
    damaged file keeps every chunk that is intact: one with its summary is read chunk by chunk,
    skipping the damaged ones; one without (a crash before `finish`) is read as a stream up to its
    first damaged or torn record."""
    path = Path(path)
    topics = None if topics is None else list(topics)
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, validate_crcs=True)
            records = [
                LogRecord(channel.topic, m.log_time, m.publish_time, m.sequence, m.data)
                for _, channel, m in reader.iter_messages(topics=topics, log_time_order=False)
            ]
            metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
            return LogContents(records, metadata, recovered=False)
    except Exception:
        contents = _by_chunks(path) or _by_stream(path)
    if topics is not None:
        contents.records = [r for r in contents.records if r.topic in topics]
    return contents


def _records_of(stream, channels: dict[int, Channel], records: list[LogRecord], metadata: dict) -> None:
    """Append the messages and metadata a `StreamReader` yields until it ends or raises."""
    for record in stream.records:
        if isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, McapMessage):
            topic = channels[record.channel_id].topic
            records.append(LogRecord(topic, record.log_time, record.publish_time, record.sequence, record.data))
        elif isinstance(record, Metadata):
            metadata[record.name] = dict(record.metadata)


def _by_chunks(path: Path) -> LogContents | None:
    """Each chunk the summary indexes, read on its own (with its CRC checked); None without a
    readable summary."""
    with open(path, "rb") as f:
        try:
            summary = SeekingReader(f).get_summary()
        except Exception:
            return None
        if summary is None or not summary.chunk_indexes:
            return None
        channels, records, metadata = dict(summary.channels), [], {}
        damaged = []
        for index in summary.chunk_indexes:
            f.seek(index.chunk_start_offset)
            raw = f.read(index.chunk_length)
            kept = len(records)
            try:
                _records_of(
                    StreamReader(io.BytesIO(raw), skip_magic=True, validate_crcs=True), channels, records, metadata
                )
            except EndOfFile:
                pass  # the chunk's bytes end there: read in full
            except Exception:
                del records[kept:]  # a damaged chunk: none of its messages, rather than some
                damaged.append(index)
        for index in summary.metadata_indexes:
            f.seek(index.offset)
            try:
                _records_of(
                    StreamReader(io.BytesIO(f.read(index.length)), skip_magic=True), channels, records, metadata
                )
            except Exception:
                continue  # EndOfFile after the record, or a damaged one: keep what was read
    spans = ", ".join(f"bytes {c.chunk_start_offset}-{c.chunk_start_offset + c.chunk_length}" for c in damaged[:3])
    more = f" and {len(damaged) - 3} more" if len(damaged) > 3 else ""
    damage = (
        f"{len(damaged)} of {len(summary.chunk_indexes)} chunks damaged ({spans}{more}): skipped, "
        f"{len(records)} messages kept"
        if damaged
        else f"an index is damaged; every chunk is intact, {len(records)} messages kept"
    )
    return LogContents(records, metadata, recovered=True, damage=damage)


def _by_stream(path: Path) -> LogContents:
    channels: dict[int, Channel] = {}
    records: list[LogRecord] = []
    metadata: dict[str, dict[str, str]] = {}
    size = path.stat().st_size
    with open(path, "rb") as f:
        try:
            _records_of(StreamReader(f, validate_crcs=True), channels, records, metadata)
            where = size
        except EndOfFile:
            where = size  # torn at the end: the crash of a mission that never finished its log
        except Exception:
            where = f.tell()
    if where >= size:
        damage = f"the file was not finished (a crash): {len(records)} messages kept, up to its last complete chunk"
    else:
        damage = f"damaged near byte {where} of {size}: {len(records)} messages kept, those before it"
    return LogContents(records, metadata, recovered=True, damage=damage)
