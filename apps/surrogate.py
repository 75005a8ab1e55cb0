"""The surrogate server app: answers GP queries on nearsub/<community>/surrogate (docs/design.md).

    python -m nearsub.apps.surrogate [--model PATH] --community NAME --connect ENDPOINT [--instance NAME]
    python -m nearsub.apps.surrogate [--model PATH] --run RUNFILE [--instance NAME]

Each query is a `SurrogateQuery` (common/surrogate/query.py) with a batch of points; the whole batch
is predicted at once and answered with a `SurrogateReply`; a batch of more than
`services.MAX_BATCH` points is refused with an error reply that says the cap, before its values are
checked or predicted. The same queryable answers
nearsub/<community>/surrogate/discrepancy with the residual GP alone (the LF-in-the-loop kind's
delta, which the increment mode adds to the LF it evaluates itself; `apps.services`) and
nearsub/<community>/surrogate/kind with the model's kind. The sim's once-a-step queries come as
publications instead (`query.request_key`, answered on the client's `query.reply_key`, a cheaper
round trip than a get); both ways reach the same handler (`answer`). A malformed query gets an
error reply naming the field and value, and the server carries on. Without --model the shipped model is
used, or, until one ships, the analytic test fixture (with a warning). The server stops on
SIGTERM/SIGINT, when its parent dies (PR_SET_PDEATHSIG) or when the launcher's token goes.
"""

from __future__ import annotations

import argparse
import sys
from typing import NoReturn

from nearsub.apps.entry import AppError, load_run, run_app
from nearsub.apps.services import MAX_BATCH, discrepancy_key, kind_key
from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Bus, Publisher, app_endpoints, signal_self
from nearsub.common.runtime.processes import leave
from nearsub.common.surrogate.domain import constraints_ok, in_domain
from nearsub.common.surrogate.model import (
    Prediction,
    Surrogate,
    answer_query,
    decode_query,
    encode_reply,
    load_surrogate,
    surrogate_key,
)
from nearsub.common.surrogate.modelfile import ModelFileError
from nearsub.common.surrogate.query import encode_refusal, reply_key, request_of, requests_key, split_request_key

# Error replies are cut to this many characters: a 100,000-point batch of NaNs would otherwise
# name every value (a nearsub choice; the first errors say what is wrong).
MAX_ERROR_CHARS = 2000


def answer_discrepancy(
    surrogate: Surrogate, payload: bytes, source: str = "surrogate", max_points: int = MAX_BATCH
) -> bytes:
    """`Surrogate.discrepancy` of a query's points, as a `SurrogateReply` (mean and std of delta,
    the flags of the points). Raises MessageError for a malformed or oversized query, TypeError
    for a model without the LF in the loop."""
    query = decode_query(payload, max_points, "surrogate discrepancy query")
    points = query.points
    mean, std = surrogate.discrepancy(points, return_std=True)
    answer = Prediction(mean, std, in_domain(points, surrogate.bounds), constraints_ok(points))
    return encode_reply(query, answer, surrogate.output_names, surrogate.model_id, source)


def answer(surrogate: Surrogate, what: str, payload: bytes, instance: str = "surrogate") -> bytes:
    """The server's answer to a `what` ("predict", "discrepancy" or "kind") query, asked either
    way (the queryable or a publication). Raises MessageError (a ValueError) for a malformed or
    oversized query, ValueError for a prediction the reply refuses (not finite), TypeError for a
    discrepancy of a model without the LF in the loop."""
    if what == "predict":
        return answer_query(surrogate, payload, instance, MAX_BATCH)
    if what == "discrepancy":
        return answer_discrepancy(surrogate, payload, instance)
    if what == "kind":
        return surrogate.kind.encode()
    raise ValueError(f"request {what!r}: not one of predict, discrepancy, kind")


def serve(bus: Bus, community: str, surrogate: Surrogate, instance: str = "surrogate") -> NoReturn:
    """Answer queries until the process is stopped; the liveliness token
    nearsub/<community>/alive/surrogate/<instance> says the server is up."""
    key = surrogate_key(community)
    # The queryable on the key itself, .../discrepancy and .../kind, and the published requests.
    requests = bus.serve(f"{key}/**", requests_key(community))
    bus.on_liveliness_lost(keys.alive(community, "launcher", "*"), signal_self())
    bus.token(keys.alive(community, "surrogate", instance))
    print(
        f"[{instance}] serving {key}: model {surrogate.model_id} from {surrogate.source} "
        f"({surrogate.loaded.provenance.get('method', 'no method recorded')})",
        flush=True,
    )
    queried = {key: "predict", discrepancy_key(community): "discrepancy", kind_key(community): "kind"}
    # A declared publisher per client's reply key (put on one costs less than a session put);
    # the client subscribed to it before it asked (`Bus.put_reply`).
    replies: dict[str, Publisher] = {}
    while True:
        request = requests.recv()
        if request.query is not None:
            what, client = queried.get(request.key, "predict"), None
        else:
            what, client = split_request_key(request.key)
        try:
            found = answer(surrogate, what, request.payload, instance)
        # MessageError is a ValueError, as is a prediction the reply refuses (not finite), which
        # must not stop the server either; TypeError: no discrepancy in this kind of model.
        except (TypeError, ValueError) as exc:
            text = str(exc)
            if len(text) > MAX_ERROR_CHARS:
                text = text[:MAX_ERROR_CHARS] + f" ... ({len(text) - MAX_ERROR_CHARS} more characters)"
            print(f"[{instance}] rejected query: {text}", file=sys.stderr, flush=True)
            if client is None:
                request.reply_error(text)
                continue
            found = encode_refusal(request_of(request.payload), text)
        if client is None:
            request.reply(found)
        else:
            if (publisher := replies.get(client)) is None:
                publisher = replies[client] = bus.publisher(reply_key(community, client))
            publisher.put(found)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="nearsub surrogate server: GP predictions of X', Y', N'")
    parser.add_argument("--model", help="surrogate model file (default: the shipped model)")
    parser.add_argument("--run", help="run configuration written by `nearsub launch` (community and endpoints)")
    parser.add_argument("--community", help="mission (community) name; overrides --run")
    parser.add_argument("--connect", action="append", metavar="ENDPOINT", help="router endpoint; overrides --run")
    parser.add_argument("--instance", default="surrogate", help="instance name for the liveliness token")

    def body(args) -> int:
        community, connect, model = args.community, args.connect, args.model
        if args.run:
            run = load_run(args.run)
            community, connect = community or run.mission.name, connect or run.connect
            model = model or run.mission.surrogate.model or None
        if not community or not connect:
            parser.error("give --run RUNFILE, or --community NAME and --connect ENDPOINT")
        try:
            surrogate = load_surrogate(model)
        except ModelFileError as exc:
            raise AppError(str(exc), 2) from None
        with Bus(app_endpoints(connect)) as bus:
            serve(bus, community, surrogate, args.instance)

    return run_app(parser, body, argv)


if __name__ == "__main__":
    leave(main())
