"""`nearsub router`: a Zenoh router on its own, for missions spread over several hosts."""

from __future__ import annotations


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("router")
    p.add_argument("--listen", action="append", default=[], help="endpoint, e.g. tcp/0.0.0.0:7447")
    p.add_argument("--connect", action="append", default=[], help="other routers to join")
    p.set_defaults(func=router_command)


def router_command(args) -> int:
    from nearsub.apps.router import serve

    return serve(args.listen or ["tcp/127.0.0.1:7447"], args.connect)
