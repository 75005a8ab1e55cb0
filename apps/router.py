"""A Zenoh router in a Python process: no zenohd can be installed offline (docs/design.md,
"Transport").

`nearsub launch` starts one on loopback port 0 and waits for the `--ready-file` it writes once it
listens: the endpoints it really listens on (read back from its own admin space), so the launcher
neither guesses a free port nor sleeps. With `--credentials FILE` it admits only sessions that
present the `user:password` in FILE (Zenoh's user/password authentication; docs/design.md,
"Transport"). `nearsub router --listen ENDPOINT` runs one by hand, for example to join apps on
several hosts.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import time
from pathlib import Path

from nearsub.apps.entry import AppError, run_app
from nearsub.common.runtime.bus import Bus, BusError, make_config
from nearsub.common.runtime.processes import leave, prepare_process


def write_ready(path: str | Path, endpoints: list[str]) -> None:
    """Write the endpoints as a JSON list, atomically: a reader sees the whole file or none."""
    path = Path(path)
    partial = path.with_name(path.name + ".partial")
    partial.write_text(json.dumps(endpoints))
    os.replace(partial, path)


def serve(
    listen: list[str],
    connect: list[str] = (),
    with_parent: bool = False,
    ready_file: str | None = None,
    credentials: str | None = None,
) -> int:
    """Route until SIGINT/SIGTERM; `with_parent` also stops when the launcher process dies."""
    # A list, not a threading.Event: a handler that runs while the main thread is inside the
    # Event's set or wait (a second signal of the stop ladder) would deadlock on its lock.
    stop: list[int] = []
    if with_parent:
        prepare_process()
    signal.signal(signal.SIGTERM, lambda signum, _: stop.append(signum))
    signal.signal(signal.SIGINT, lambda signum, _: stop.append(signum))
    config = make_config("router", connect=connect, listen=listen, admin_space=True, credentials=credentials)
    with Bus(config) as bus:
        endpoints = bus.locators() or list(listen)
        if ready_file:
            write_ready(ready_file, endpoints)
        admits = f"sessions with the credentials in {credentials}" if credentials else "any session (no credentials)"
        print(f"router listening on {', '.join(endpoints)}, admitting {admits}", flush=True)
        while not stop:
            time.sleep(0.2)
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="nearsub Zenoh router")
    parser.add_argument("--listen", action="append", default=[], help="endpoint, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--connect", action="append", default=[], help="other routers to join")
    parser.add_argument("--with-parent", action="store_true", help="exit when the parent process dies")
    parser.add_argument("--ready-file", help="write the endpoints listened on (JSON list) here once listening")
    parser.add_argument("--credentials", help="admit only sessions with the user:password in this file (mode 0600)")

    def body(args) -> int:
        try:
            return serve(
                args.listen or ["tcp/127.0.0.1:7447"], args.connect, args.with_parent, args.ready_file, args.credentials
            )
        except BusError as exc:  # a malformed endpoint, a port taken: bad input, one line naming it
            raise AppError(str(exc), 2) from None
        except OSError as exc:  # the ready file cannot be written
            raise AppError(str(exc), 1) from None

    # Not prepared for a launcher unless --with-parent: a router of its own stops on SIGINT/SIGTERM.
    return run_app(parser, body, argv, prepare=False, name="router")


if __name__ == "__main__":
    leave(main())
