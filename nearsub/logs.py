"""Mission logs in Python: one pandas DataFrame per topic in one call, or the raw messages.

A mission log is an MCAP file whose channels hold msgpack maps (docs/design.md, "Topics and
messages" and "Transport"). This module decodes them, so nobody has to write a decoder::

    from nearsub.logs import read_frames

    frames = read_frames("logs/alpha-20260101-120000-42/alpha.mcap")     # {topic: DataFrame}
    state = frames["nearsub/alpha/remus100/state"]                        # u, v, r, x, y, psi, ...
    state.plot(x="y", y="x")
    frames = read_frames(path, topics="nearsub/alpha/*/state")           # a Zenoh key expression

Each vehicle of a mission has its own topics (nearsub/<community>/<vehicle>/<leaf>), so its own
frames: `read_frames(path, "nearsub/alpha/*/state")` gives one state frame per vehicle.

Each frame has one row per message in log-time order: `log_time` (simulated seconds, the MCAP log
time) and then the message's fields (`schema_version`, `step`, `t`, `source`, then the model's
own; angles in radians, SI units). Nested maps are flattened with dots (an event's `data.x`).
`read_frames` needs pandas, which is an optional extra: `pip install 'nearsub[pandas]'`.

Without pandas, `read_messages` yields `(topic, log_time, fields)` tuples, and `DecoderFactory`
plugs nearsub's decoding into the `mcap` package's own reader::

    from mcap.reader import make_reader
    from nearsub.logs import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, fields in reader.iter_decoded_messages():
            print(channel.topic, message.log_time / 1e9, fields)

A log cut short by a crash is read up to its last complete chunk (`read_log`).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import msgpack
from mcap.decoder import DecoderFactory as _McapDecoderFactory

from nearsub.common.runtime.logfile import INVALID_SUFFIX, read_log

if TYPE_CHECKING:
    import pandas
    from mcap.records import Schema

__all__ = [
    "DecoderFactory",
    "decode_payload",
    "flatten",
    "read_frames",
    "read_messages",
    "read_metadata",
    "topic_filter",
]

PANDAS_MISSING = "nearsub.logs.read_frames needs pandas, an optional extra: pip install 'nearsub[pandas]'"


def decode_payload(data: bytes) -> Any:
    """A nearsub message payload (msgpack) as Python values: a dict of the message's fields."""
    return msgpack.unpackb(data, raw=False)


class DecoderFactory(_McapDecoderFactory):
    """Decodes nearsub's `msgpack` channels for `mcap.reader.make_reader(..., decoder_factories=[...])`.
    Payloads the logger could not decode are logged on `<topic>#invalid` channels as
    `application/octet-stream`; those come back as their raw bytes."""

    def decoder_for(self, message_encoding: str, schema: Schema | None) -> Callable[[bytes], Any] | None:
        if message_encoding == "msgpack":
            return decode_payload
        if message_encoding == "application/octet-stream":
            return bytes
        return None


def flatten(value: dict, prefix: str = "") -> dict:
    """{'a': 1, 'd': {'x': 2}, 'e': {}} -> {'a': 1, 'd.x': 2} (an empty map gives no column)."""
    out = {}
    for key, item in value.items():
        name = f"{prefix}{key}"
        if isinstance(item, dict):
            out.update(flatten(item, name + "."))
        else:
            out[name] = item
    return out


def topic_filter(topics: str | list[str] | None, name: str = "topics") -> Callable[[str], bool]:
    """A test of topics against Zenoh key expressions (None: every topic), by Zenoh's own rules
    (`zenoh.KeyExpr.includes`); a topic `<key>#invalid` is tested by its key. A pattern that is not
    a key expression raises ValueError naming `name` and the pattern."""
    if topics is None:
        return lambda topic: True
    import zenoh

    patterns = [topics] if isinstance(topics, str) else list(topics)
    exprs = []
    for pattern in patterns:
        try:
            exprs.append(zenoh.KeyExpr(pattern))
        except zenoh.ZError as exc:
            raise ValueError(f"{name} {pattern!r}: not a key expression ({str(exc).split(' at ')[0]})") from None

    def wanted(topic: str) -> bool:
        key = zenoh.KeyExpr(topic.removesuffix(INVALID_SUFFIX))
        return any(e.includes(key) for e in exprs)

    return wanted


def read_messages(
    path: str | Path, topics: str | list[str] | None = None, invalid: bool = False
) -> Iterator[tuple[str, float, Any]]:
    """`(topic, log_time [s], fields)` for every message of a log in log-time order (messages at the
    same time in file order). `topics`: a Zenoh key expression or a list of them (wildcards `*`
    and `**`). With `invalid`, payloads the logger could not decode come too, as raw bytes on
    their `<topic>#invalid` topic."""
    wanted = topic_filter(topics)
    records = sorted(read_log(path).records, key=lambda r: r.log_time)  # sorted() is stable
    for r in records:
        bad = r.topic.endswith(INVALID_SUFFIX)
        if bad and not invalid:
            continue
        if wanted(r.topic):
            yield r.topic, r.sim_time, (bytes(r.data) if bad else decode_payload(r.data))


def read_frames(path: str | Path, topics: str | list[str] | None = None) -> dict[str, pandas.DataFrame]:
    """{topic: DataFrame} for a mission log, one row per message (see the module's text)."""
    try:
        import pandas
    except ImportError:
        raise ModuleNotFoundError(PANDAS_MISSING) from None
    rows: dict[str, list[dict]] = {}
    for topic, log_time, fields in read_messages(path, topics):
        row = {"log_time": log_time}
        row.update(flatten(fields) if isinstance(fields, dict) else {"value": fields})
        rows.setdefault(topic, []).append(row)
    return {topic: pandas.DataFrame.from_records(items) for topic, items in sorted(rows.items())}


def read_metadata(path: str | Path) -> dict[str, dict]:
    """The log's metadata records by name: `mission` (with `resolved`, the resolved mission, parsed
    from its JSON), `run` (version, start time), `mission_file` and `outcome`."""
    metadata: dict[str, dict] = {name: dict(values) for name, values in read_log(path).metadata.items()}
    mission = metadata.get("mission", {})
    if isinstance(mission.get("resolved"), str):
        mission["resolved"] = json.loads(mission["resolved"])
    return metadata
