"""`nearsub completion bash|zsh|tcsh`: a completion script for every subcommand and option.

eval "$(nearsub completion bash)"                     # bash, now; or add it to ~/.bashrc
nearsub completion zsh > "${fpath[1]}/_nearsub"       # zsh, then restart the shell
"""

from __future__ import annotations


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("completion", help="print a shell completion script")
    p.add_argument("shell", choices=("bash", "zsh", "tcsh"))
    p.set_defaults(func=completion_command)


def completion_command(args) -> int:
    import shtab

    from ..cli import build_parser

    print(shtab.complete(build_parser(every=True), shell=args.shell))
    return 0
