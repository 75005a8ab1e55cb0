"""The README a new user reads first: its two commands, its five-minute walk and its links.

Each command of the walk is parsed by `nearsub`'s own parser (options, choices and positionals as
`nearsub` would read them, nothing run), and the missions it names are shipped ones, so the walk
works from any folder. The running of those commands is what tests/test_live.py, test_poke.py,
test_runtime_pause.py and test_viewer.py check, each against a launched mission."""

from __future__ import annotations

import re
import shlex

import pytest

from conftest import ROOT
from nearsub.tools.cli import build_parser

README = ROOT / "README.md"
SHIPPED = {path.stem for path in (ROOT / "missions").glob("*.toml")}


def _section(title: str) -> str:
    text = README.read_text()
    start = text.index(f"\n## {title}\n")
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else len(text)]


def walk_commands() -> list[list[str]]:
    """The commands of the walk's code block, without their comments or a trailing `&`."""
    block = re.search(r"```bash\n(.*?)```", _section("Five minutes with nearsub"), re.S).group(1)
    commands = []
    for line in block.splitlines():
        words = shlex.split(line, comments=True)
        if words and words[-1] == "&":
            words.pop()
        if words:
            commands.append(words)
    return commands


def test_the_readme_opens_with_the_two_commands_that_work_on_a_fresh_machine():
    first = README.read_text().splitlines()[:4]
    assert first[0] == "```bash"
    assert first[1].startswith("bash tools/run.sh") and first[2].startswith("bash tools/test.sh")
    assert (ROOT / "tools" / "run.sh").is_file() and (ROOT / "tools" / "test.sh").is_file()
    assert len(README.read_text().splitlines()) <= 200


def test_the_walk_covers_launch_view_tap_poke_swap_and_log():
    used = {words[1] for words in walk_commands()}
    assert {"launch", "view", "tap", "poke", "swap", "log", "clock"} <= used


@pytest.mark.parametrize("words", walk_commands(), ids=lambda words: " ".join(words[1:4]))
def test_each_command_of_the_walk_parses_and_names_a_shipped_mission(words):
    assert words[0] == "nearsub"
    argv = words[1:]
    try:
        args = build_parser(argv[0]).parse_args(argv)
    except SystemExit as exc:
        pytest.fail(f"nearsub does not parse {' '.join(words)!r} (exit {exc.code})")
    named = getattr(args, "mission", None)
    if named is not None and not named.endswith(".mcap"):
        assert named in SHIPPED, f"{' '.join(words)}: {named!r} is not a shipped mission"


def test_every_local_link_of_the_readme_leads_to_a_file():
    targets = re.findall(r"\]\(([^)#]+)\)", README.read_text())
    local = [t for t in targets if not t.startswith("http")]
    assert local and all((ROOT / t).exists() for t in local), [t for t in local if not (ROOT / t).exists()]
