"""The `nearsub` command line: every subcommand registers from its module, the listing and the light
tools' parsers load no numerical or transport library, and bad input gets one line and exit 2."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ALPHA, nearsub
from nearsub.tools.cli import TOOLS, build_parser

HEAVY = ("numpy", "scipy", "zenoh", "matplotlib")
# Tools whose parser and whose answer without a running mission need none of HEAVY.
LIGHT_TOOLS = (
    "launch",
    "tap",
    "log",
    "swap",
    "clock",
    "router",
    "al-bench",
    "maps",
    "envelope",
    "validate",
    "foxglove",
    "cfd",
)


def loaded_after(code: str) -> list[str]:
    """The HEAVY modules a fresh interpreter has loaded after running `code`."""
    probe = f"import sys\n{code}\nprint('loaded:', *(m for m in {HEAVY!r} if m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()[-1].split()[1:]


def test_help_lists_every_subcommand_without_loading_numpy_scipy_zenoh_or_matplotlib():
    code = "from nearsub.tools.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass"
    assert loaded_after(code) == []
    listing = nearsub("--help").stdout
    assert all(name in listing for name in TOOLS)


@pytest.mark.parametrize("command", LIGHT_TOOLS)
def test_a_light_tools_parser_loads_no_heavy_module(command):
    assert loaded_after(f"from nearsub.tools.cli import build_parser\nbuild_parser({command!r})") == []


def test_tap_list_with_nothing_running_says_so_without_loading_zenoh(runtime_dir):
    code = (
        "from nearsub.tools.cli import main\n"
        "assert main(['tap', 'list', 'alpha']) == 2, 'exit code'"  # the registry is empty
    )
    env_code = f"import os\nos.environ['NEARSUB_RUNTIME_DIR'] = {str(runtime_dir)!r}\n{code}"
    assert loaded_after(env_code) == []
    done = nearsub("tap", "list", "alpha")
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "nearsub tap list: no running mission named 'alpha' (none is running; start one with `nearsub launch`)"
    )


@pytest.mark.parametrize("command", sorted(TOOLS))
def test_every_subcommand_builds_its_parser_from_its_module(command):
    parser = build_parser(command)
    with pytest.raises(SystemExit) as stop:
        parser.parse_args([command, "--help"])
    assert stop.value.code == 0


def test_an_unknown_subcommand_is_named():
    done = nearsub("nope")
    assert done.returncode == 2
    assert "invalid choice: 'nope'" in done.stderr and "Traceback" not in done.stderr


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["clock", "nobody", "status"], "nearsub clock: no running mission named 'nobody'"),
        (["launch", "missing.toml"], "nearsub launch: "),
        (["envelope", "--behaviour", "drift"], "nearsub envelope: --behaviour 'drift' is not one of waypoints"),
        (["al-bench", "sudoku"], "nearsub al-bench: unknown problem 'sudoku'"),
        (
            ["al-bench", "park", "--hf-samples", "10", "--reference", "40"],
            "nearsub al-bench: --reference: count(s) [40]",
        ),
        (["al-bench", "park", "--methods", "nmmf,greedy"], "nearsub al-bench: unknown method(s) ['greedy']"),
        # A malformed endpoint, named with the form wanted (was: Zenoh's Json5Err traceback).
        *(
            (argv, f"nearsub {argv[0]}: {role} endpoint 'garbage' is not <protocol>/<address>, e.g. tcp/127.0.0.1:7447")
            for argv, role in [
                (["tap", "list", "alpha", "--connect", "garbage"], "connect"),
                (["tap", "echo", "alpha", "nearsub/alpha/**", "--connect", "garbage"], "connect"),
                (["clock", "alpha", "status", "--connect", "garbage"], "connect"),
                (["poke", "alpha", "x=1", "--vehicle", "v", "--connect", "garbage"], "connect"),
                (["view", "alpha", "--connect", "garbage"], "connect"),
                (["foxglove", "alpha", "--connect", "garbage"], "connect"),
                (["swap", "alpha", "helm", "--connect", "garbage"], "connect"),
                (["router", "--listen", "garbage"], "listen"),
                (["router", "--connect", "garbage"], "connect"),
            ]
        ),
        # A port out of range, refused at once (was: 30 s of retries before "cannot reach").
        (
            ["tap", "list", "alpha", "--connect", "tcp/127.0.0.1:99999"],
            "nearsub tap: connect endpoint 'tcp/127.0.0.1:99999' ",
        ),
        (["router", "--credentials", "/nonexistent/x.cred"], "nearsub router: --credentials /nonexistent/x.cred: "),
        (["router", "--credentials", "/"], "nearsub router: --credentials /: is a directory"),
        (["launch", str(ALPHA), "--log", str(ALPHA)], f"nearsub launch: --log {ALPHA}: cannot make a folder there"),
        (["launch", str(ALPHA), "--view-port", "8080"], "nearsub launch: --view-port 8080: add --view"),
        # Finite but beyond what a mission can count or pace: named as typed, not as a --set.
        (["launch", str(ALPHA), "--until", "1e307"], "nearsub launch: --until 1e+307: field 'time_limit' = 1e+307: "),
        (["launch", str(ALPHA), "--warp", "1e300"], "nearsub launch: --warp 1e+300: field 'warp' = 1e+300: "),
        (["tap", "pub", "a", "v/desired", "{}", "--raw-hex", "zz"], "nearsub tap pub: --raw-hex 'zz': not hex"),
        (["tap", "pub", "a", "nearsub/a/v/desired", "[1,2]"], "nearsub tap pub: value '[1,2]': not a JSON object"),
        (
            ["tap", "pub", "a", "v/desired", '{"psi_d": 0.5, "psi_d_deg": 30}'],
            "nearsub tap pub: value: psi_d and psi_d_deg both given: give one",
        ),
        (["tap", "pub", "a", "desired", "{}"], "nearsub tap pub: key desired: a message goes to one key; name the"),
        (["tap", "pub", "a", "nearsub/b/v/desired", "{}"], "nearsub tap pub: key nearsub/b/v/desired: not a key of"),
        (
            ["tap", "pub", "alpha", "clock/tick", '{"step": 999999999}'],
            "nearsub tap pub: nearsub/alpha/clock/tick: a Tick is the lock-step's own",
        ),
        (["clock", "alpha", "warp", "1e308"], "nearsub clock: warp needs a number from 0 to 1e+06"),
        (["poke", "alpha", "X=nan", "--vehicle", "v"], "nearsub poke: 'X=nan': nan is not a finite number"),
        (["poke", "alpha", "=5", "--vehicle", "v"], "nearsub poke: '=5': variable name '' is not letters"),
        (["tap", "echo", "alpha", "//bad"], "nearsub tap echo: 'nearsub/alpha///bad' is not a key expression: empty"),
        (["tap", "hz", "alpha", "a/b*c"], "nearsub tap hz: 'nearsub/alpha/a/b*c' is not a key expression: `*` may"),
        (["tap", "echo", "alpha", "stat"], "nearsub tap echo: key stat: not a short key (state, "),
        # A mission file stands for its name; a name that is not running names the running ones.
        (["clock", str(ALPHA), "status"], "nearsub clock: no running mission named 'alpha' (none is running"),
        (["clock", "missing.toml", "status"], "nearsub clock: MISSION missing.toml: "),
    ],
)
def test_bad_input_gets_one_line_and_exit_2(runtime_dir, argv, message):
    done = nearsub(*argv)
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith(message) and len(done.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["envelope", "--grid", "forty"], "argument --grid: wants NxM"),
        (["swap", "alpha", "helm", "--with", "period"], "argument --with: item 'period' is not key=value"),
        (["log", "play", "x.mcap", "--from", "nan"], "argument --from: wants a finite number >= 0, got 'nan'"),
        (["log", "play", "x.mcap", "--from", "inf"], "argument --from: wants a finite number >= 0, got 'inf'"),
        (["log", "play", "x.mcap", "--to", "inf"], "argument --to: wants a finite number >= 0, got 'inf'"),
        (["log", "play", "x.mcap", "--warp", "-1"], "argument --warp: wants a finite number >= 0, got '-1'"),
        (["tap", "hz", "alpha", "k", "--window", "-3"], "argument --window: wants a whole number >= 2, got '-3'"),
        (["tap", "hz", "alpha", "k", "--window", "0"], "argument --window: wants a whole number >= 2, got '0'"),
        (["tap", "hz", "alpha", "k", "--duration", "-1"], "argument --duration: wants a finite number > 0, got '-1'"),
        (["tap", "echo", "alpha", "k", "--count", "-1"], "argument --count: wants a whole number >= 1, got '-1'"),
        (["tap", "echo", "alpha", "k", "--count", "0"], "argument --count: wants a whole number >= 1, got '0'"),
        (["tap", "echo", "alpha", "k", "--timeout", "-1"], "argument --timeout: wants a finite number > 0, got '-1'"),
        (["tap", "list", "alpha", "--sample", "-1"], "argument --sample: wants a finite number >= 0, got '-1'"),
        (["tap", "list", "alpha", "--sample", "nan"], "argument --sample: wants a finite number >= 0, got 'nan'"),
        (["clock", "alpha", "pause", "--at-step", "-5"], "argument --at-step: wants a whole number >= 1"),
        (["clock", "alpha", "pause", "--at-step", "1" + "0" * 30], "argument --at-step: wants a whole number >= 1"),
        (["swap", "alpha", "helm", "--at-step", "1" + "0" * 30], "argument --at-step: wants a whole number >= 1"),
        (["launch", "m.toml", "--until", "-1"], "argument --until: wants a finite number > 0, got '-1'"),
        (["launch", "m.toml", "--warp", "-1"], "argument --warp: wants a finite number >= 0, got '-1'"),
        (["launch", "m.toml", "--foxglove-port", "-1"], "argument --foxglove-port: wants a whole number >= 0"),
        (["bench", "pipeline", "--repeats", "0"], "argument --repeats: wants a whole number >= 1, got '0'"),
        (["bench", "helm", "--repeats", "-1"], "argument --repeats: wants a whole number >= 1, got '-1'"),
        (["bench", "envelope", "--duration", "-1"], "argument --duration: wants a finite number > 0, got '-1'"),
        (["bench", "envelope", "--sample", "0"], "argument --sample: wants a whole number >= 1, got '0'"),
        (["bench", "envelope", "--grid", "0x0"], "argument --grid: wants NxM"),
        (["surrogate", "validate", "--seed", "-1"], "argument --seed: wants a whole number >= 0, got '-1'"),
    ],
)
def test_a_malformed_option_value_is_named_by_argparse(argv, message):
    done = nearsub(*argv)
    assert done.returncode == 2
    assert message in done.stderr and "Traceback" not in done.stderr


def test_version_prints_the_package_version():
    from nearsub import __version__

    result = subprocess.run([sys.executable, "-m", "nearsub", "--version"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and result.stdout.strip() == f"nearsub {__version__}"


def bash_completer(env: dict | None = None):
    """`complete(*words)`: what `nearsub completion bash` offers for the last word, as bash runs it
    (with `env`; the script calls `nearsub`, which the PATH finds beside this interpreter)."""
    script = nearsub("completion", "bash")
    assert script.returncode == 0, script.stderr
    env = dict(env or os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")

    def complete(*words: str) -> list[str]:
        line = " ".join(words)
        probe = (
            f"{script.stdout}\nCOMP_WORDS=({' '.join(repr(w) for w in words)}); COMP_CWORD={len(words) - 1}; "
            f'COMP_LINE={line!r}; COMP_POINT=${{#COMP_LINE}}; _shtab_nearsub; echo "${{COMPREPLY[@]}}"'
        )
        done = subprocess.run(["bash", "-c", probe], capture_output=True, text=True, timeout=60, env=env)
        assert done.returncode == 0, done.stderr
        return done.stdout.split()

    return complete


def test_bash_completion_completes_subcommands_and_choices():
    """`nearsub completion bash` as bash runs it: the subcommands, and an option's choices."""
    complete = bash_completer()

    assert complete("nearsub", "lo") == ["log"]
    assert set(TOOLS) <= set(complete("nearsub", ""))
    assert complete("nearsub", "log", "export", "a.mcap", "--format", "") == ["csv", "json", "alog", "foxglove"]
    assert complete("nearsub", "log", "") == ["info", "export", "play", "plot"]


def test_bash_completion_offers_the_running_missions_names_for_mission(runtime_dir, tmp_path):
    """Every MISSION completes with the names in the launcher's registry (a launcher alive: this
    test's process); launch and validate with the shipped missions' names and the files."""
    import json

    for name, pid in (("sea_trial", os.getpid()), ("sunk", 2**22 + 1)):  # the second's launcher is gone
        entry = {"community": name, "connect": ["tcp/127.0.0.1:1"], "pid": pid, "log": str(tmp_path / "x.mcap")}
        (runtime_dir / f"{name}.json").write_text(json.dumps(entry))
    complete = bash_completer(dict(os.environ, NEARSUB_RUNTIME_DIR=str(runtime_dir)))
    for words in (
        ("clock", "s"),
        ("swap", ""),
        ("poke", "sea"),
        ("view", "sea"),
        ("foxglove", ""),
        ("moos", "watch", ""),
        *(("tap", action, "") for action in ("list", "echo", "hz", "watch", "pub")),
    ):
        assert complete("nearsub", *words) == ["sea_trial"], words
    assert complete("nearsub", "launch", "overtake_stern_n") == ["overtake_stern_nuv"]
    assert complete("nearsub", "validate", "launch_t") == ["launch_two"]
    assert complete("nearsub", "launch", str(ALPHA)[:-3]) == [str(ALPHA)]  # a mission file too


def test_every_command_names_its_mission_first_and_a_misspelt_name_gets_did_you_mean(runtime_dir, tmp_path):
    """One way of naming a running mission: MISSION, the first positional, one help text; a name
    that is not running is one line naming it, the closest running one and the running ones."""
    import json

    from nearsub.tools.support.missions import MISSION_HELP

    parser = build_parser(every=True)
    commands = [["tap", a] for a in ("list", "echo", "hz", "watch", "pub")]
    commands += [["clock"], ["swap"], ["poke"], ["view"], ["foxglove"], ["moos", "watch"]]
    for words in commands:
        sub = parser
        for word in words:
            sub = next(a for a in sub._actions if a.dest and a.choices and word in a.choices).choices[word]
        first = next(a for a in sub._actions if not a.option_strings)
        assert (first.dest, first.metavar) == ("mission", "MISSION") and first.help.startswith(MISSION_HELP), words
    entry = {"community": "sea_trial", "connect": ["tcp/127.0.0.1:1"], "pid": os.getpid(), "log": "x.mcap"}
    (runtime_dir / "sea_trial.json").write_text(json.dumps(entry))
    calls = (("clock", ["sea_tria", "status"]), ("tap echo", ["sea_tria", "state"]), ("poke", ["sea_tria", "X=1"]))
    for command, argv in calls:
        done = nearsub(*command.split(), *argv)
        assert done.returncode == 2 and done.stderr == (
            f"nearsub {command}: no running mission named 'sea_tria' (did you mean 'sea_trial'? running: sea_trial)\n"
        ), done.stderr


def test_a_mission_file_that_is_no_regular_file_or_nests_too_deeply_is_one_line_and_exit_2(runtime_dir, tmp_path):
    fifo, nested = tmp_path / "mission.fifo", tmp_path / "nested.toml"
    os.mkfifo(fifo)  # opened for reading, a FIFO blocks until a writer comes: none will
    nested.write_text("x = " + "[" * 1000 + "\n")
    for path, words in ((fifo, "not a regular file"), (nested, "nested too deeply"), (tmp_path, "not a regular file")):
        done = nearsub("launch", str(path), "--log", str(tmp_path / "logs"), timeout=30.0)
        assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr[-300:]
        assert done.stderr.startswith(f"nearsub launch: {path}: ") and words in done.stderr, done.stderr


@pytest.mark.parametrize("no_validate", [[], ["--no-validate"]])
def test_tap_pub_of_a_huge_integer_or_deeply_nested_json_is_one_line_and_exit_2(runtime_dir, no_validate):
    key = "remus100/desired"
    cases = (('{"step": ' + "1" + "0" * 30 + "}", "an integer beyond 64 bits"),
             ('{"a": ' * 3000 + "1" + "}" * 3000, "JSON nested too deeply"))  # fmt: skip
    for value, words in cases:
        done = nearsub("tap", "pub", "alpha", key, value, *no_validate)
        assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr[-300:]
        assert done.stderr.startswith("nearsub tap pub: value") and words in done.stderr, done.stderr


def test_tap_echo_on_a_terminal_prints_json_that_tap_pub_takes():
    """A person copies the value `tap echo` shows into `tap pub`: JSON, not a Python dict, with
    the simulated time to the millisecond (it printed t=23.450000000000003 and {'x': ...}), and
    the heading in degrees under a name that says so (psi_d_deg), which `tap pub` takes back."""
    import json
    import math

    import msgpack
    import pytest

    from nearsub.common.runtime.fields import from_people
    from nearsub.common.runtime.messages import Desired, decode
    from nearsub.tools.commands.tap import _for_people, terminal_line

    desired = Desired(step=469, t=469 * 0.05, source="helm", u_d=1.2, psi_d=0.5)
    key = "nearsub/alpha/remus100/desired"
    shown = _for_people(key, desired.model_dump(mode="json"), None)
    line = terminal_line({"key": key, "vehicle": "remus100", "t": desired.t, "value": shown})
    shown_key, when, value = line.split("  ", 2)
    assert (shown_key, when) == (key, "t=23.450")
    typed = json.loads(value)
    assert typed["psi_d_deg"] == round(math.degrees(0.5), 3) and "psi_d" not in typed
    pasted = decode(msgpack.packb(from_people("Desired", typed)), Desired, key)
    assert pasted.psi_d == pytest.approx(0.5, abs=math.radians(0.001))  # shown to a thousandth of a degree
    assert pasted.model_copy(update={"psi_d": 0.5}) == desired
    assert _for_people(key, desired.model_dump(mode="json"), ["psi_d"]) == {"psi_d_deg": typed["psi_d_deg"]}
    assert _for_people(key, desired.model_dump(mode="json"), ["u_d", "psi_d"]) == {"u_d": 1.2, "psi_d_deg": 28.648}
    unreadable = {"key": key, "vehicle": None, "error": "not valid msgpack"}
    assert terminal_line(unreadable) == f"{key}  t=-  not valid msgpack"
