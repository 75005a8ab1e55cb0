"""The surrogate server's query and reply messages and the prediction they carry.

Kept apart from `surrogate.model` (which loads the GP stack) so that a process asking the server
(`apps.services`) imports numpy and msgpack only.

On the wire a query and a reply are msgpack maps whose arrays travel as raw little-endian
float64 bytes (the flags as one byte each): the sim asks once a step, and building and checking
lists of floats field by field (pydantic) cost more than the round trip's own work. The server
checks a query cheaply (shape, row count, finite values) and names the first bad field and value;
it refuses to send a non-finite answer, so a client checks only a reply's shapes. The bytes carry
the doubles unchanged, so a reply equals the in-process prediction bit for bit.

Two ways to ask, one codec and one server-side handler (apps/surrogate.py): a Zenoh get on the
queryable `surrogate_key` (tools, sweeps, `nearsub bench surrogate`), or the sim's once-a-step
request/reply pair of publications, a cheaper round trip than a get's (`nearsub bench surrogate`
times both): the client publishes the query on `request_key` and the server publishes the reply
on the client's `reply_key`. Those keys hold a verbatim chunk ("@rpc", "@reply"), which no
wildcard matches, so the logger's nearsub/<community>/** does not record each step's query and
reply (the sim's forces carry the answer). A query carries a
`request` number that its reply (or refusal) echoes, so a late answer to an earlier query is never
taken for the current one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np

from nearsub.common.runtime import keys
from nearsub.common.runtime.messages import MessageError, unpack_map
from nearsub.common.surrogate.domain import INPUT_NAMES, _as_inputs


class ServiceError(RuntimeError):
    """A service the mission depends on (the surrogate server) is missing or failed."""


class Refusal(MessageError):
    """The server's error answer to a published query: its text names the field and value;
    `request` is the query's number (None when the query was too malformed to read it)."""

    def __init__(self, text: str, request: int | None):
        super().__init__(text)
        self.request = request


# Largest batch one query may carry (a nearsub choice: bounds the server's memory per query,
# 4.8 MB of float64; a 10,000-point sweep is 10 queries).
MAX_QUERY_POINTS = 100_000
# Version of the query and reply format. 1 carried the arrays as lists of floats; a query or
# reply of another version is refused, so a mixed installation fails loudly.
QUERY_VERSION = 2
WIRE_FLOAT = np.dtype("<f8")


def surrogate_key(community: str) -> str:
    """The server's queryable: nearsub/<community>/surrogate (a service key, docs/design.md, "Keys")."""
    return f"{keys.community_root(community)}/surrogate"


# What a published request asks for: the full prediction or the residual GP alone (the
# LF-in-the-loop kind's delta, `Surrogate.discrepancy`).
REQUESTS = ("predict", "discrepancy")


def request_key(community: str, what: str, client: str) -> str:
    """Where `client` publishes its `what` queries (module docstring)."""
    return f"{surrogate_key(community)}/@rpc/{what}/{client}"


def requests_key(community: str) -> str:
    """Every client's published queries: the server's subscription."""
    return f"{surrogate_key(community)}/@rpc/*/*"


def reply_key(community: str, client: str) -> str:
    """Where the server publishes its answers to `client`'s published queries."""
    return f"{surrogate_key(community)}/@reply/{client}"


def split_request_key(key: str) -> tuple[str, str]:
    """(what, client) of a `request_key`."""
    what, client = key.rsplit("/", 2)[-2:]
    return what, client


# ------------------------------------------------------------------------------- prediction
@dataclass(frozen=True)
class Prediction:
    """Answers for n points: mean and std (n, 3) (None if not asked), and the two flags (n,).

    For points outside the bounds or constraints, mean and std are still the GP's posterior at
    that very point (no clipping, no substitution): far from the data the RBF GP reverts to the
    training mean and its std grows towards the prior std, so the numbers stay finite and honest,
    and the flags say not to trust them. Non-finite inputs give NaN mean and std.
    """

    mean: np.ndarray
    std: np.ndarray | None
    in_domain: np.ndarray
    constraints_ok: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """(n,) inside the bounds and the constraints: the region the model was trained on."""
        return self.in_domain & self.constraints_ok


# -------------------------------------------------------------------------------- messages
QUERY_FIELDS = ("schema_version", "step", "t", "source", "request", "points")


@dataclass(slots=True)  # not frozen: a frozen dataclass costs a few us more to build, per query
class SurrogateQuery:
    """A batch of points to predict at: `points` (n, 6), rows [R_long, R_lat, u_kn, psi_deg,
    d_ratio, ld_ratio] (INPUT_NAMES order, units of table 4.2), finite, 1..MAX_QUERY_POINTS rows.

    Rows: a row is one vehicle state, maps to a numpy (n, 6) array without reordering, and a bad
    value is named by its position (field 'points.<row>.<column>'). step, t and source are the
    sender's; the reply echoes step, t and request (the sender's number for the query)."""

    points: np.ndarray
    step: int = 0
    t: float = 0.0
    source: str = ""
    request: int = 0


@dataclass(slots=True)
class SurrogateReply:
    """Answers to a `SurrogateQuery`, row for row: mean and std (n, len(output_names)) of the
    non-dimensional coefficients, and the flags (n,) (see `Prediction` for out-of-domain points),
    read-only views of the reply's bytes. model_id names the model (a content hash), source is the
    server instance, request the query's number."""

    request: int
    step: int
    t: float
    source: str
    mean: np.ndarray
    std: np.ndarray
    in_domain: np.ndarray
    constraints_ok: np.ndarray
    output_names: list[str]
    model_id: str

    def prediction(self) -> Prediction:
        """The reply as a `Prediction`."""
        return Prediction(self.mean, self.std, self.in_domain, self.constraints_ok)


def _rows(data: bytes, width: int) -> np.ndarray:
    """A read-only (n, width) view of float64 bytes."""
    return np.frombuffer(data, dtype=WIRE_FLOAT).reshape(-1, width)


def _first_non_finite(name: str, values: np.ndarray) -> str | None:
    """ "field '<name>.<row>.<column>' = <value>: ..." for the first non-finite value, or None."""
    if np.isfinite(values).all():
        return None
    row, column = np.argwhere(~np.isfinite(values))[0]
    return f"field '{name}.{row}.{column}' = {float(values[row, column])!r}: not a finite number"


def _request(raw: dict, where: str) -> int:
    request = raw.get("request", 0)
    if type(request) is not int or request < 0:
        raise MessageError(f"{where}: field 'request' = {request!r}: a whole number >= 0 is required")
    return request


def _header(raw: dict, where: str) -> tuple[int, float, str]:
    """The checked schema_version, step, t and source of an unpacked query or reply."""
    version = raw.get("schema_version", QUERY_VERSION)
    if version != QUERY_VERSION:
        raise MessageError(
            f"{where}: field 'schema_version' = {version!r}: unsupported (this build speaks {QUERY_VERSION})"
        )
    step, t, source = raw.get("step"), raw.get("t"), raw.get("source", "")
    if type(step) is not int or step < 0:
        raise MessageError(f"{where}: field 'step' = {step!r}: a whole number >= 0 is required")
    if type(t) not in (int, float) or not math.isfinite(t):
        raise MessageError(f"{where}: field 't' = {t!r}: a finite number is required")
    if not isinstance(source, str):
        raise MessageError(f"{where}: field 'source' = {source!r}: text is required")
    return step, float(t), source


def encode_query(points: Any, step: int = 0, t: float = 0.0, source: str = "", request: int = 0) -> bytes:
    """msgpack bytes of a query for points (n, 6) or (6,)."""
    rows = np.ascontiguousarray(_as_inputs(points), dtype=WIRE_FLOAT)
    fields = {
        "schema_version": QUERY_VERSION,
        "step": step,
        "t": t,
        "source": source,
        "request": request,
        "points": rows.tobytes(),
    }
    return msgpack.packb(fields)


def decode_query(payload: bytes, max_points: int = MAX_QUERY_POINTS, where: str = "surrogate query") -> SurrogateQuery:
    """Check a query (raises MessageError naming the field and value). A batch of more than
    `max_points` rows is refused saying the cap, before its values are looked at."""
    raw = unpack_map(payload, where)
    if extra := [name for name in raw if name not in QUERY_FIELDS]:
        raise MessageError(f"{where}: field '{extra[0]}': not a field of a query (fields: {', '.join(QUERY_FIELDS)})")
    step, t, source = _header(raw, where)
    request = _request(raw, where)
    data = raw.get("points")
    if not isinstance(data, bytes):
        shown = repr(data) if len(repr(data)) < 80 else repr(data)[:80] + "..."
        raise MessageError(f"{where}: field 'points' = {shown}: the rows as little-endian float64 bytes are required")
    row_bytes = len(INPUT_NAMES) * WIRE_FLOAT.itemsize
    n, rest = divmod(len(data), row_bytes)
    if rest or n == 0:
        raise MessageError(
            f"{where}: field 'points': {len(data)} bytes; 1 or more rows of {len(INPUT_NAMES)} float64 "
            f"({row_bytes} bytes each) are required"
        )
    if n > max_points:
        raise MessageError(f"points: {n} points in one query; this server answers at most {max_points} per query")
    points = _rows(data, len(INPUT_NAMES)).astype(float)  # the model's own copy
    if bad := _first_non_finite("points", points):
        raise MessageError(f"{where}: {bad}")
    return SurrogateQuery(points, step, t, source, request)


def encode_reply(
    query: SurrogateQuery, prediction: Prediction, output_names: list[str], model_id: str, source: str
) -> bytes:
    """msgpack bytes of the reply to `query`; raises ValueError, naming the field and value, for a
    non-finite mean or std (never sent: a client does not check them again)."""
    for name, values in (("mean", prediction.mean), ("std", prediction.std)):
        if bad := _first_non_finite(name, values):
            raise ValueError(f"surrogate reply: {bad}")
    fields = {
        "schema_version": QUERY_VERSION,
        "request": query.request,
        "step": query.step,
        "t": query.t,
        "source": source,
        "mean": np.ascontiguousarray(prediction.mean, dtype=WIRE_FLOAT).tobytes(),
        "std": np.ascontiguousarray(prediction.std, dtype=WIRE_FLOAT).tobytes(),
        "in_domain": np.asarray(prediction.in_domain, dtype=bool).tobytes(),
        "constraints_ok": np.asarray(prediction.constraints_ok, dtype=bool).tobytes(),
        "output_names": list(output_names),
        "model_id": model_id,
    }
    return msgpack.packb(fields)


def decode_reply(payload: bytes, where: str = "surrogate reply") -> SurrogateReply:
    """A server reply's arrays, with their shapes checked (raises MessageError naming the field);
    the values are the server's, which checked them before sending. A refusal (`encode_refusal`)
    raises `Refusal` with its text."""
    raw = unpack_map(payload, where)
    if "error" in raw:
        request = raw.get("request")
        raise Refusal(str(raw["error"]), request if type(request) is int else None)
    request = _request(raw, where)
    step, t, source = _header(raw, where)
    names, model_id = raw.get("output_names"), raw.get("model_id")
    if not isinstance(names, list) or not names or not all(isinstance(name, str) for name in names):
        raise MessageError(f"{where}: field 'output_names' = {names!r}: a list of names is required")
    if not isinstance(model_id, str):
        raise MessageError(f"{where}: field 'model_id' = {model_id!r}: text is required")
    arrays = [raw.get(name) for name in ("mean", "std", "in_domain", "constraints_ok")]
    if not all(isinstance(array, bytes) for array in arrays):
        raise MessageError(f"{where}: fields 'mean', 'std', 'in_domain' and 'constraints_ok' must be bytes")
    n, width = len(arrays[2]), len(names) * WIRE_FLOAT.itemsize
    if len(arrays[3]) != n or len(arrays[0]) != n * width or len(arrays[1]) != n * width:
        raise MessageError(
            f"{where}: in_domain has {n} rows but constraints_ok has {len(arrays[3])}, mean "
            f"{len(arrays[0]) / width:g} and std {len(arrays[1]) / width:g} rows of {len(names)} values"
        )
    mean, std = _rows(arrays[0], len(names)), _rows(arrays[1], len(names))
    in_domain, constraints_ok = (np.frombuffer(array, dtype=bool) for array in arrays[2:])
    return SurrogateReply(request, step, t, source, mean, std, in_domain, constraints_ok, names, model_id)


def request_of(payload: bytes) -> int | None:
    """The `request` number of a query that may be malformed (for its refusal), or None."""
    try:
        request = msgpack.unpackb(payload).get("request")
    except Exception:  # not a msgpack map: nothing to echo
        return None
    return request if type(request) is int else None


def encode_refusal(request: int | None, text: str) -> bytes:
    """msgpack bytes of the server's error answer to a published query (`decode_reply` raises it)."""
    return msgpack.packb({"schema_version": QUERY_VERSION, "request": request, "error": text})
