"""`nearsub router`: a Zenoh router on its own, for missions spread over several hosts."""

from __future__ import annotations


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("router")
    p.add_argument("--listen", action="append", default=[], help="endpoint, e.g. tcp/0.0.0.0:7447")
    p.add_argument("--connect", action="append", default=[], help="other routers to join")
    p.add_argument(
        "--credentials",
        metavar="FILE",
        help="admit only sessions with the user:password in FILE; a missing FILE is created with random ones",
    )
    p.set_defaults(func=router_command)


def router_command(args) -> int:
    import sys
    from pathlib import Path

    from nearsub.apps.router import serve
    from nearsub.common.runtime import credentials
    from nearsub.common.runtime.bus import BusError

    if args.credentials and not Path(args.credentials).exists():
        credentials.create(args.credentials)
        print(f"created {args.credentials}: copy it (mode 0600) to every host that joins", flush=True)
    try:
        return serve(args.listen or ["tcp/127.0.0.1:7447"], args.connect, credentials=args.credentials)
    except BusError as exc:
        print(f"nearsub router: {exc}", file=sys.stderr)
        return 2
