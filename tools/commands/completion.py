"""`nearsub completion bash|zsh|tcsh`: a completion script for every subcommand and option.

eval "$(nearsub completion bash)"                     # bash, now; or add it to ~/.bashrc
nearsub completion zsh > "${fpath[1]}/_nearsub"       # zsh, then restart the shell

A command's MISSION completes with the running missions' names, which the script asks of
`nearsub completion --names running` (the launcher's registry, as the commands resolve them);
`launch` and `validate` with the shipped missions' names (`--names shipped`) and files.
"""

from __future__ import annotations


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("completion", help="print a shell completion script")
    p.add_argument("shell", nargs="?", choices=("bash", "zsh", "tcsh"))
    p.add_argument(
        "--names",
        choices=("running", "shipped"),
        help="instead, the names the script completes: the running missions, or the shipped ones (one a line)",
    )
    p.set_defaults(func=completion_command)


def completion_command(args) -> int:
    if args.names is not None:
        print("\n".join(mission_names(args.names)))
        return 0
    if args.shell is None:
        from ..support.errors import InputError

        raise InputError("give the shell: bash, zsh or tcsh (or --names running|shipped)")
    import shtab

    from ..cli import build_parser

    print(shtab.complete(build_parser(every=True), shell=args.shell))
    return 0


def mission_names(kind: str) -> list[str]:
    """The running missions' names (the registry's), or the shipped missions' names."""
    if kind == "running":
        from ..support import registry

        return sorted(registry.running())
    from nearsub.common.mission.schema import SHIPPED_MISSIONS

    return sorted(path.stem for path in SHIPPED_MISSIONS.glob("*.toml"))
