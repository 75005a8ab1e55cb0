"""Services the lock-stepped apps call over the bus: the surrogate server."""

from __future__ import annotations

import numpy as np

from nearsub.common.runtime.bus import Bus, ReplyError
from nearsub.common.runtime.messages import MessageError
from nearsub.common.surrogate import model as sg
from nearsub.common.surrogate.interaction import ServiceError


class RemoteSurrogate:
    """The surrogate server, asked over the bus (one query per call, the whole batch in it).
    It answers with the numbers `Surrogate.predict` gives in-process, bit for bit."""

    def __init__(self, bus: Bus, community: str, timeout: float = 5.0):
        self.key = sg.surrogate_key(community)
        self._querier = bus.querier(self.key, timeout)

    def predict(self, inputs: np.ndarray, return_std: bool = True) -> sg.Prediction:
        try:
            payload = self._querier.ask(sg.encode_query(inputs))
            return sg.decode_reply(payload).prediction()
        except (ReplyError, MessageError) as exc:
            raise ServiceError(f"surrogate server at {self.key}: {exc}") from None
