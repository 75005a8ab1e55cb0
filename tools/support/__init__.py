"""What the subcommands share on the command line.

- arguments: argparse types for numbers (a value out of range is one line naming the option).
- outputs: the checks on a path a command writes (never over its input or the shipped docs).
- errors: InputError, the bad input `cli` prints as one line, exit 2.
- tables: the console the tools print their tables on.
- registry: where running missions are found (one JSON file per mission) and their names claimed.
- missions: MISSION, the first positional of every command that addresses a running mission.
- connect: a bus to a running mission, by endpoint or by name (through the registry).
- caller: request/reply to the clock or an app of a running mission.
- schedulers: the `--scheduler ADDRESS` check of the commands that run Dask tasks.
- topics: the topic a command is given (a key expression, or a short key such as `state`).
- log_input: the mission logs a command is given (checked paths, `--topic`, `--vehicle`, a log's mission).
- kernels: every compiled kernel of a mission's processes, into numba's cache once per install.
"""
