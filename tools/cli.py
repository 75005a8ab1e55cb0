"""The `nearsub` command line: one program, one subcommand per tool.

Subcommand X lives in the module named in TOOLS, which exports `add_parser(subparsers)`: it adds
its parser and sets `func`, which runs it. Only the module of the subcommand being run is imported,
and a tool imports its heavy modules (numpy, scipy, zenoh, matplotlib) only when it runs, so that
`nearsub --help` and a tool's `--help` answer at once. A LookupError a tool raises (no such
mission, problem or behaviour; `errors.InputError` for any bad input) is printed as one line
naming it, with exit code 2, and so is a bus that cannot be reached or is lost mid-command
(BusError: the text names the endpoint).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from nearsub import __version__
from nearsub.common.runtime.processes import single_blas_thread

# subcommand: (module in tools/commands/, one line for `nearsub --help`)
TOOLS = {
    "launch": ("launch", "run a mission file as separate processes"),
    "tap": ("tap", "watch a running mission: list, echo, hz, pub"),
    "log": ("log", "inspect, export and plot mission logs"),
    "swap": ("swap", "replace a running helm, pid or sim without stopping the mission"),
    "poke": ("poke", "set mission variables of a running helm (uPokeDB)"),
    "clock": ("clock", "status, pause or resume a running mission's clock"),
    "router": ("router", "run a Zenoh router (for multi-host setups)"),
    "surrogate": ("surrogate", "inspect and query a surrogate model file"),
    "train": ("train", "train the interaction surrogate with NMMF (LF + HF physics)"),
    "al-bench": ("al_bench", "NMMF vs myopic MF vs HF-only active learning on thesis benchmarks"),
    "maps": ("maps", "colour maps of thesis figures 4-4 to 4-11 as PNGs"),
    "campaign": ("campaign", "NMMF training with your own CFD as the high fidelity"),
    "cfd": ("cfd", "RANS CFD on OpenFOAM: SUBOFF validation and two-body cases"),
    "envelope": ("envelope", "safe operating envelopes around the submarine (PNG, CSV, JSON)"),
    "validate": ("validate", "physics validation cases (thesis 5.10) and scenario checks"),
    "bench": ("bench", "benchmarks that print measured figures"),
    "view": ("view", "live map of a running mission, or replay of a log, in the browser"),
    "foxglove": ("foxglove", "serve a running mission to Foxglove over its WebSocket protocol"),
    "completion": ("completion", "print a shell completion script: bash, zsh or tcsh"),
    "moos": ("moos", "nearsub in a MOOS-IvP community: the sim as a MOOS app (moos extra)"),
    "lf-field": ("lf_field", "tabulate the LF's submarine field into the file the package ships"),
}


def build_parser(command: str | None = None, every: bool = False) -> argparse.ArgumentParser:
    """The parser of `nearsub`, with the full parser of `command` (importing its module) and the
    other subcommands listed by name and help line only; with `every`, all of them in full (for
    shell completion)."""
    parser = argparse.ArgumentParser(prog="nearsub", description="UUV simulation near a moving submarine")
    parser.add_argument("--version", action="version", version=f"nearsub {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add = sub.add_parser  # each tool's parser gets its help line, which completion lists it by
    sub.add_parser = lambda name, **kw: add(name, **({"help": TOOLS[name][1]} if name in TOOLS else {}) | kw)
    for name, (module, help_line) in TOOLS.items():
        if every or name == command:
            importlib.import_module(f"{__package__}.commands.{module}").add_parser(sub)
        else:
            sub.add_parser(name, help=help_line, add_help=False)
    return parser


def main(argv=None) -> int:
    # Before any tool imports numpy. numba's threads stay: a sweep in this process spreads its
    # batches over them; the processes it starts get one (`processes.spawn_app`, task_client).
    single_blas_thread(numba=False)
    argv = sys.argv[1:] if argv is None else list(argv)
    command = argv[0] if argv and argv[0] in TOOLS else None
    args = build_parser(command).parse_args(argv)
    try:
        return args.func(args)
    except LookupError as exc:
        action = getattr(args, f"{args.command.replace('-', '_')}_command", None)  # `log export`
        name = f"{args.command} {action}" if isinstance(action, str) else args.command
        print(f"nearsub {name}: {exc.args[0] if exc.args else exc}", file=sys.stderr)
        return 2
    except Exception as exc:
        # The bus could not be opened, or the router vanished mid-command: one line naming the
        # endpoint (BusError's text). Only a tool that loaded the bus can raise it; the others
        # must not pay for importing Zenoh here.
        bus = sys.modules.get("nearsub.common.runtime.bus")
        if bus is None or not isinstance(exc, bus.BusError):
            raise
        print(f"nearsub {args.command}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
