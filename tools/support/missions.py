"""MISSION, the one way a command names a running mission (`tap`, `clock`, `swap`, `poke`, `view`,
`foxglove`, `moos watch`): its first positional argument, with one metavar and help text, completed
in the shell with the names of the running missions (`nearsub completion`, from the registry the
commands resolve names from). It is the name `nearsub launch` registered (the mission file's
`name`, or `--set name=...`); a mission file (a path, or a name ending in .toml) stands for the
name it holds. `launch` and `validate` take a mission file or a shipped mission's name instead
(`completion("shipped", files=True)`)."""

from __future__ import annotations

from pathlib import Path

from .errors import InputError

MISSION_HELP = "a running mission's name, as `nearsub launch` printed it (or its mission file)"


def completion(names: str, files: bool = False) -> dict:
    """A shtab `.complete` that offers the names `nearsub completion --names NAMES` prints (the
    running missions, from the registry; or the shipped ones), and with `files` the files too."""
    command = f"nearsub completion --names {names} 2>/dev/null"
    function = f"_nearsub_{names}{'_or_files' if files else ''}"
    lines = [f'compgen -W "$({command})" -- "$1"'] + (['compgen -f -- "$1"'] if files else [])
    bash = f"{function}() {{\n" + "".join(f"  {line}\n" for line in lines) + "}\n"
    return {
        "bash": function,
        # shtab puts it in a double-quoted spec: escaped, it runs when completing, not when loaded
        "zsh": "{compadd -- \\$(" + command + ")" + ("; _files" if files else "") + "}",
        "tcsh": f"`{command}`",  # tcsh completes one list: the names
        "preamble": {"bash": bash},
    }


def add_mission_argument(parser, or_log: bool = False) -> None:
    """MISSION, the first positional of a command that addresses a running mission; `or_log`:
    a log file to replay is accepted instead (`view`)."""
    help_text = MISSION_HELP + ("; or a log file (.mcap) to replay" if or_log else "")
    action = parser.add_argument("mission", metavar="MISSION", help=help_text)
    action.complete = completion("running", files=or_log)


def add_shipped_completion(action) -> None:
    """Complete a mission-file argument (`launch`, `validate`) with the shipped missions' names and
    the files."""
    action.complete = completion("shipped", files=True)


def is_mission_file(text: str) -> bool:
    """Whether MISSION names a mission file (a path, or a name ending in .toml) rather than a name."""
    path = Path(text)
    return path.suffix == ".toml" or len(path.parts) > 1


def load_mission_file(text: str):
    """The mission of the file MISSION names; bad input names the file and the problem."""
    from nearsub.common.mission.schema import MissionError, load_mission

    try:
        return load_mission(text)
    except MissionError as exc:
        raise InputError(f"MISSION {text}: {exc}") from None


def mission_name(text: str) -> str:
    """The running mission's name MISSION stands for: the name a mission file holds, else the
    text itself."""
    return load_mission_file(text).name if is_mission_file(text) else text


def mission_of(args):
    """The mission MISSION names: its file's, else the running mission's (from the launcher's
    run file); None for a name reached through `--connect`, or a run file that is gone."""
    if is_mission_file(args.mission):
        return load_mission_file(args.mission)
    if args.connect:
        return None
    from . import registry

    return mission_of_run(registry.lookup(args.mission))


def mission_of_run(entry: dict):
    """The mission of a running launcher's registry entry: its run file sits beside the log it writes."""
    from nearsub.common.mission.schema import RunConfig

    run_file = Path(entry.get("log", "")).parent / "run.json"
    try:
        return RunConfig.load(run_file).mission
    except (OSError, ValueError):
        return None


def resolve_mission(args) -> str:
    """`args.mission` replaced by the name it stands for (`mission_name`), which it returns."""
    args.mission = mission_name(args.mission)
    return args.mission
