"""The `nearsub` command line: one program, one subcommand per tool.

Tool modules are imported only when their subcommand runs, so `nearsub --help` stays fast.
"""

from __future__ import annotations

import argparse
import os
import sys

# One BLAS thread per process: the apps and tools are many small processes on few cores, where
# OpenBLAS threading made a GP fit 25x slower (measured on the 2-core machine). Override by
# setting the variable.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def _launch(args):
    from .launch import launch_command

    return launch_command(args)


def _tap(args):
    from . import tap

    return {"list": tap.tap_list, "echo": tap.tap_echo, "hz": tap.tap_hz, "pub": tap.tap_pub}[args.tap_command](args)


def _log(args):
    if args.log_command == "plot":
        from .plot import plot_command

        return plot_command(args)
    from . import logtool

    return {"info": logtool.info_command, "export": logtool.export_command}[args.log_command](args)


def _swap(args):
    from .swap import swap_command

    return swap_command(args)


def _clock(args):
    from .swap import clock_command

    return clock_command(args)


def _router(args):
    from nearsub.apps.router import serve

    return serve(args.listen or ["tcp/127.0.0.1:7447"], args.connect)


def _bench_hydro(args):
    from .hydro_bench import benchmark_fidelities

    benchmark_fidelities()
    return 0


def _validate(args):
    from .validate import validate_command

    return validate_command(args)


def _bench(args):
    from .bench import bench_command

    return bench_command(args)


def build_parser() -> argparse.ArgumentParser:
    from .connect import add_connect_arguments

    parser = argparse.ArgumentParser(prog="nearsub", description="UUV simulation near a moving submarine")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("launch", help="run a mission file as separate processes")
    p.add_argument("mission", help="mission file (TOML)")
    p.add_argument("--warp", type=float, help="time warp: 0 = as fast as possible, 1 = real time")
    p.add_argument("--until", type=float, metavar="T", help="stop after T simulated seconds")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a mission setting")
    p.add_argument("--log", default="logs", metavar="DIR", help="folder for logs (default: logs)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=_launch)

    p = sub.add_parser("tap", help="watch a running mission: list, echo, hz, pub")
    tap = p.add_subparsers(dest="tap_command", required=True)
    t = tap.add_parser("list", help="apps and topics alive now")
    add_connect_arguments(t)
    t.add_argument("--json", action="store_true")
    t = tap.add_parser("echo", help="print messages of a key expression (wildcards * and **)")
    t.add_argument("key")
    t.add_argument("--field", help="print only this field (dotted path)")
    t.add_argument("--count", type=int, help="stop after N messages")
    t.add_argument("--timeout", type=float, help="stop after S wall seconds")
    t.add_argument("--json", action="store_true", help="JSON lines (the default when piped)")
    add_connect_arguments(t)
    t = tap.add_parser("hz", help="message rates per key, in simulated time")
    t.add_argument("key")
    t.add_argument("--window", type=int, default=100, help="samples per rate estimate")
    t.add_argument("--duration", type=float, default=5.0, help="wall seconds to listen")
    t.add_argument("--json", action="store_true")
    add_connect_arguments(t)
    t = tap.add_parser("pub", help="publish one message by hand, validated against its schema")
    t.add_argument("key")
    t.add_argument("value", nargs="?", default="{}", help="JSON object of fields")
    t.add_argument("--no-validate", action="store_true", help="send the JSON as msgpack without checking it")
    t.add_argument("--raw-hex", help="send these bytes instead (fault injection)")
    add_connect_arguments(t)
    p.set_defaults(func=_tap)

    p = sub.add_parser("log", help="inspect and export mission logs")
    lg = p.add_subparsers(dest="log_command", required=True)
    t = lg.add_parser("info", help="topics, counts, rates and outcome of a log")
    t.add_argument("log")
    t.add_argument("--json", action="store_true")
    t = lg.add_parser("export", help="export as csv, json lines or MOOS alog")
    t.add_argument("log")
    t.add_argument("--format", choices=("csv", "json", "alog"), default="json")
    t.add_argument("--topic", help="key expression to select (wildcards allowed)")
    t.add_argument("-o", "--output", help="output file (json, alog) or folder (csv)")
    t = lg.add_parser("plot", help="trajectory in the submarine frame and time series (PNG)")
    t.add_argument("log")
    t.add_argument("-o", "--output", help="PNG file (default: next to the log)")
    t.add_argument("--title")
    p.set_defaults(func=_log)

    p = sub.add_parser("swap", help="replace a running app (the helm) without stopping the mission")
    p.add_argument("community", help="mission name")
    p.add_argument("app", help="role to replace, e.g. helm")
    p.add_argument("--with", dest="with_", metavar="SPEC", help="settings of the new app: key=value,key=value")
    p.add_argument("--behaviour", help="shorthand for --with behaviour=NAME")
    p.add_argument("--at-step", type=int, help="swap when the clock reaches this step (default: now)")
    p.add_argument("--timeout", type=float, default=120.0, help="wall seconds to wait for the swap")
    p.add_argument("--json", action="store_true")
    p.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="router endpoint (default: from the registry)"
    )
    p.set_defaults(func=_swap)

    p = sub.add_parser("clock", help="status, pause or resume a running mission's clock")
    p.add_argument("community", help="mission name")
    p.add_argument("action", choices=("status", "pause", "resume"))
    p.add_argument("--at-step", type=int, help="with pause: pause when the clock reaches this step")
    p.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="router endpoint (default: from the registry)"
    )
    p.set_defaults(func=_clock)

    p = sub.add_parser("router", help="run a Zenoh router (for multi-host setups)")
    p.add_argument("--listen", action="append", default=[], help="endpoint, e.g. tcp/0.0.0.0:7447")
    p.add_argument("--connect", action="append", default=[], help="other routers to join")
    p.set_defaults(func=_router)

    from . import albench, train
    from .surrogate import add_bench_parser, add_parser

    add_parser(sub)
    train.add_parser(sub)
    albench.add_parser(sub)
    from . import campaign, maps

    maps.add_parser(sub)
    campaign.add_parser(sub)
    from . import envelope

    envelope.add_parser(sub)

    p = sub.add_parser("validate", help="physics validation cases (thesis 5.10) and scenario checks")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_validate)

    p = sub.add_parser("bench", help="benchmarks that print measured figures")
    b = p.add_subparsers(dest="bench_command", required=True)
    t = b.add_parser("pipeline", help="lock-stepped steps per second of a mission at warp 0")
    t.add_argument("--mission", default=None, help="mission file (default: missions/alpha.toml)")
    t.add_argument("--repeats", type=int, default=3)
    t.add_argument("--json", action="store_true")
    add_bench_parser(b)
    from .bench import add_envelope_bench_parser

    add_envelope_bench_parser(b)
    t = b.add_parser("hydro", help="cost per evaluation of the low- and high-fidelity hydrodynamic models")
    t.set_defaults(func=_bench_hydro)
    p.set_defaults(func=_bench)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except LookupError as exc:
        print(f"nearsub {args.command}: {exc.args[0] if exc.args else exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
