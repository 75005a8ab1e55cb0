"""A Zenoh router in a Python process: no zenohd can be installed offline (zenoh-notes.md 2).

`nearsub launch` starts one on a free loopback port; `nearsub router --listen ENDPOINT` runs one
by hand, for example to join apps on several hosts.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from nearsub.apps.shell import prepare_process
from nearsub.common.runtime.bus import Bus, make_config


def serve(listen: list[str], connect: list[str] = (), with_parent: bool = False) -> int:
    """Route until SIGINT/SIGTERM; `with_parent` also stops when the launcher process dies."""
    stop = threading.Event()
    if with_parent:
        prepare_process()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    config = make_config("router", connect=connect, listen=listen, admin_space=True)
    with Bus(config):
        print(f"router listening on {', '.join(listen)}", flush=True)
        while not stop.wait(0.5):
            pass
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="nearsub Zenoh router")
    parser.add_argument("--listen", action="append", default=[], help="endpoint, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--connect", action="append", default=[], help="other routers to join")
    parser.add_argument("--with-parent", action="store_true", help="exit when the parent process dies")
    args = parser.parse_args(argv)
    listen = args.listen or ["tcp/127.0.0.1:7447"]
    try:
        return serve(listen, args.connect, args.with_parent)
    except Exception as exc:  # e.g. the port is taken: say so in one line
        print(f"router: cannot listen on {listen}: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    raise SystemExit(main())
