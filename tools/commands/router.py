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
    from pathlib import Path

    from nearsub.apps.router import serve
    from nearsub.common.runtime import credentials

    from ..support.errors import InputError

    path = Path(args.credentials) if args.credentials else None
    if path is not None and path.is_dir():
        raise InputError(f"--credentials {path}: is a directory, not a credentials file")
    if path is not None and not path.exists():
        try:
            credentials.create(path)
        except OSError as exc:
            raise InputError(f"--credentials {path}: cannot create it ({exc.strerror})") from None
        print(f"created {path}: copy it (mode 0600) to every host that joins", flush=True)
    # A BusError (a malformed endpoint, a port taken) is printed by the command line: one line, exit 2.
    return serve(args.listen or ["tcp/127.0.0.1:7447"], args.connect, credentials=args.credentials)
