"""The surrogate server's query and reply messages and the prediction they carry.

Kept apart from `surrogate.model` (which loads the GP stack) so that a process asking the server
(`apps.services`) imports numpy and pydantic only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from pydantic import Field, model_validator
from pydantic.types import FiniteFloat

from nearsub.common.runtime import keys
from nearsub.common.runtime.messages import FiniteMessage, decode, encode
from nearsub.common.surrogate.domain import INPUT_NAMES, _as_inputs


class ServiceError(RuntimeError):
    """A service the mission depends on (the surrogate server) is missing or failed."""


# Largest batch one query may carry (a nearsub choice: bounds the server's memory per query,
# about 1 MB of msgpack; a 10,000-point sweep is 10 queries).
MAX_QUERY_POINTS = 100_000


def surrogate_key(community: str) -> str:
    """The server's queryable: nearsub/<community>/surrogate (a service key, docs/design.md, "Keys")."""
    return f"{keys.community_root(community)}/surrogate"


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
Point = Annotated[list[FiniteFloat], Field(min_length=len(INPUT_NAMES), max_length=len(INPUT_NAMES))]


class SurrogateQuery(FiniteMessage):
    """A batch of points to predict at: `points` is a list of rows [R_long, R_lat, u_kn, psi_deg,
    d_ratio, ld_ratio] (INPUT_NAMES order, units of table 4.2), finite, 1..MAX_QUERY_POINTS rows.

    Rows rather than a dict of columns: a row is one vehicle state, maps to a numpy (n, 6) array
    without reordering, and a bad value is named by its position (field 'points.<row>.<column>').
    The header (schema_version, step, t, source) is the sender's; the reply echoes step and t.
    """

    points: Annotated[list[Point], Field(min_length=1, max_length=MAX_QUERY_POINTS)]


class SurrogateReply(FiniteMessage):
    """Answers to a `SurrogateQuery`, row for row: mean and std (n, len(output_names)) of the
    non-dimensional coefficients, and the flags (n,) (see `Prediction` for out-of-domain points).
    model_id names the model (a content hash), source is the server instance."""

    mean: list[list[FiniteFloat]]
    std: list[list[FiniteFloat]]
    in_domain: list[bool]
    constraints_ok: list[bool]
    output_names: list[str]
    model_id: str

    @model_validator(mode="after")
    def _consistent_shapes(self) -> SurrogateReply:
        n, m = len(self.mean), len(self.output_names)
        if len(self.std) != n or len(self.in_domain) != n or len(self.constraints_ok) != n:
            raise ValueError(
                f"mean has {n} rows but std has {len(self.std)}, in_domain {len(self.in_domain)}, "
                f"constraints_ok {len(self.constraints_ok)}"
            )
        bad = next((i for i, row in enumerate(self.mean + self.std) if len(row) != m), None)
        if bad is not None:
            raise ValueError(f"row {bad % n} of {'mean' if bad < n else 'std'} does not have {m} values")
        return self

    def prediction(self) -> Prediction:
        """The reply as numpy arrays."""
        return Prediction(
            np.array(self.mean, dtype=float).reshape(-1, len(self.output_names)),
            np.array(self.std, dtype=float).reshape(-1, len(self.output_names)),
            np.array(self.in_domain, dtype=bool),
            np.array(self.constraints_ok, dtype=bool),
        )


def encode_query(points: Any, step: int = 0, t: float = 0.0, source: str = "") -> bytes:
    """msgpack bytes of a SurrogateQuery for points (n, 6) or (6,)."""
    rows = _as_inputs(points).tolist()
    return encode(SurrogateQuery(step=step, t=t, source=source, points=rows))


def decode_reply(payload: bytes) -> SurrogateReply:
    """Validate a server reply (raises MessageError naming the field and value)."""
    return decode(payload, SurrogateReply, "surrogate reply")
