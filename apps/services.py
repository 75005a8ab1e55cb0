"""Services the lock-stepped apps call over the bus: the surrogate server."""

from __future__ import annotations

import uuid
from collections.abc import Callable

import numpy as np

from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Bus, ReplyError
from nearsub.common.runtime.messages import MessageError
from nearsub.common.surrogate import query as sg
from nearsub.common.surrogate.domain import BOUNDS
from nearsub.common.surrogate.query import ServiceError

# The server answers at most MAX_BATCH points per query and refuses a larger batch with an error
# reply saying so (apps/surrogate.py): a client asks for one UUV's point a step, and a hostile
# 100,000-point query would otherwise hold the server for minutes.
MAX_BATCH = 1024
# Wall seconds per point of the server's costlier answer (the full prediction) for a batch of
# MAX_BATCH points of the shipped model: 1.45 ms, measured on the shared 2-core machine at a load
# average of 14.7 (docs/design.md, "Transport"). The queries' timeout leaves twice the worst
# legitimate answer, plus 2 s for the round trip and scheduling on a loaded machine.
SECONDS_PER_POINT = 1.5e-3
QUERY_TIMEOUT = 2.0 + 2 * MAX_BATCH * SECONDS_PER_POINT  # 5.07 s


def discrepancy_key(community: str) -> str:
    """The server's answers of the residual GP alone (the LF-in-the-loop kind's delta)."""
    return f"{sg.surrogate_key(community)}/discrepancy"


def kind_key(community: str) -> str:
    """The server's model kind ("lf_in_loop", "multi_fidelity" or "gp"), as UTF-8 text."""
    return f"{sg.surrogate_key(community)}/kind"


class RemoteSurrogate:
    """The surrogate server, asked over the bus (one query per call, the whole batch in it).
    It answers with the numbers `Surrogate.predict` and `Surrogate.discrepancy` give in-process,
    bit for bit (the reply carries the doubles as their bytes).

    Predictions are asked with the published request/reply pair (`query.request_key`, a cheaper
    round trip than a get), each query numbered: a reply to an earlier number (one that came after
    its query's timeout) is skipped, never taken for the current one. A server whose liveliness
    token goes ends the wait at once (a ServiceError, which ends the mission) instead of at the
    timeout. Building one asks nothing, so a sim can build its core while the server loads."""

    def __init__(self, bus: Bus, community: str, timeout: float = QUERY_TIMEOUT):
        self.key = sg.surrogate_key(community)
        client = uuid.uuid4().hex  # this client's reply key, unique on the bus
        self._keys = {what: sg.request_key(community, what, client) for what in sg.REQUESTS}
        self._rpc = bus.requester(sg.reply_key(community, client), keys.alive(community, "surrogate", "*"), timeout)
        self._kind_querier = bus.querier(kind_key(community), timeout)
        self._kind: str | None = None
        self._model_id: str | None = None
        self._request = 0

    @property
    def kind(self) -> str:
        """The served model's kind (asked once)."""
        if self._kind is None:
            try:
                self._kind = self._kind_querier.ask(b"").decode()
            except ReplyError as exc:
                raise ServiceError(f"surrogate server at {self.key}: {exc}") from None
        return self._kind

    @property
    def model_id(self) -> str:
        """The served model's content hash (from the first reply; asked if none came yet)."""
        if self._model_id is None:
            self.predict(BOUNDS.mean(axis=1))
        return self._model_id

    def _ask(self, what: str, inputs: np.ndarray) -> Callable[[], sg.SurrogateReply]:
        """Publish a `what` query now; the returned function waits for its reply."""
        self._request += 1
        number = self._request
        try:
            deadline = self._rpc.send(self._keys[what], sg.encode_query(inputs, request=number))
        except ReplyError as exc:
            raise ServiceError(f"surrogate server at {self.key}: {exc}") from None

        def reply() -> sg.SurrogateReply:
            try:
                while True:
                    try:
                        found = sg.decode_reply(self._rpc.reply(deadline))
                    except sg.Refusal as exc:
                        if exc.request == number:
                            raise
                        continue  # an earlier query's refusal
                    if found.request == number:
                        self._model_id = found.model_id
                        return found
            except (ReplyError, MessageError) as exc:
                raise ServiceError(f"surrogate server at {self.key}: {exc}") from None

        return reply

    def predict(self, inputs: np.ndarray, return_std: bool = True) -> sg.Prediction:
        return self._ask("predict", inputs)().prediction()

    def discrepancy_later(
        self, inputs: np.ndarray, return_std: bool = True
    ) -> Callable[[], tuple[np.ndarray, np.ndarray | None]]:
        """Ask the server about delta now; the returned function waits for the answer, so the
        asker computes the LF while the server predicts (`interaction.lf_in_loop_increment`)."""
        reply = self._ask("discrepancy", inputs)

        def answer() -> tuple[np.ndarray, np.ndarray | None]:
            found = reply()
            return found.mean, found.std if return_std else None

        return answer

    def discrepancy(self, inputs: np.ndarray, return_std: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """The residual GP's mean and std (n, 3) (`Surrogate.discrepancy`; the std is always sent)."""
        return self.discrepancy_later(inputs, return_std)()
