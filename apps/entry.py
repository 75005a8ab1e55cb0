"""The one entry of every app process (helm, pid, sim, clock, logger, surrogate server, router), as
ROS 2's examples have one `main` shape: parse the arguments, prepare the process
(`processes.prepare_process`), run the app's body and return its exit code, which the module's
`__main__` hands to `processes.leave`. A failure is one line naming the instance, never a traceback:

- a mission or run file the app cannot use (MissionError): exit 2;
- an AppError (an app that cannot go on, or bad input it found itself): its code;
- a router that cannot be reached (BusError): exit 1;
- Ctrl-C: 130; SIGTERM (from the launcher's stop ladder, or its death): 128 + 15, once the app's
  `with` blocks have closed its session and files.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from nearsub.common.runtime.processes import Terminated, prepare_process


class AppError(Exception):
    """An app that cannot go on; the text is one line, `code` the exit code (2: bad input)."""

    def __init__(self, text: str, code: int = 1):
        super().__init__(text)
        self.code = code


def run_app(
    parser: argparse.ArgumentParser,
    body: Callable[[argparse.Namespace], int],
    argv: list[str] | None = None,
    prepare: bool = True,
    name: str | None = None,
) -> int:
    """Parse `argv` with `parser`, prepare the process (unless `prepare` is False: the router does
    it itself when it runs under a launcher) and return `body(args)`, or the exit code of its
    failure (module docstring), printed as one line prefixed by `[instance]` (`--instance`, else
    `name`)."""
    args = parser.parse_args(argv)
    if prepare:
        prepare_process()
    name = getattr(args, "instance", None) or name or parser.prog
    try:
        return body(args)
    except AppError as exc:
        print(f"[{name}] {exc}", file=sys.stderr)
        return exc.code
    except KeyboardInterrupt:
        return 130
    except Terminated as exc:
        return exc.code
    except Exception as exc:
        code = _failure_code(exc)
        if code is None:
            raise
        print(f"[{name}] {exc}", file=sys.stderr)
        return code


def _failure_code(exc: Exception) -> int | None:
    """2 for a MissionError, 1 for a BusError, None for anything else. The modules are looked up,
    not imported: the router loads no mission schema."""
    schema = sys.modules.get("nearsub.common.mission.schema")
    if schema is not None and isinstance(exc, schema.MissionError):
        return 2
    bus = sys.modules.get("nearsub.common.runtime.bus")
    if bus is not None and isinstance(exc, bus.BusError):
        return 1
    return None


def load_run(path: str, overrides: list[str] = ()):
    """The launcher's run file (`--run`), with `overrides` (`--set KEY=VALUE`) applied; a file
    that cannot be read or is not a run file is a MissionError naming it."""
    from nearsub.common.mission.schema import MissionError, RunConfig, apply_overrides, mission_from_dict

    try:
        run = RunConfig.load(path)
    except (OSError, ValueError) as exc:
        raise MissionError(f"cannot read {path}: {exc}") from None
    if overrides:
        data = apply_overrides(run.mission.model_dump(mode="json"), list(overrides))
        run = run.model_copy(update={"mission": mission_from_dict(data, "--set")})
    return run
