"""The subcommands of `nearsub`, one module each (`cli.TOOLS` maps a subcommand to its module):
each exports `add_parser(subparsers)`, which adds its parser and sets `func`, and imports its heavy
modules only when it runs.

- launch: run a mission file as separate processes (the `launcher` package).
- tap: watch a running mission: list, echo, hz, pub.
- log: inspect, export, play and plot mission logs.
- swap: replace a running helm, pid or sim without stopping the mission.
- poke: set mission variables of a running helm.
- clock: status, pause, resume or warp of a running mission's clock.
- router: a Zenoh router on its own (several hosts).
- surrogate: inspect, query, validate and sweep a surrogate model file.
- train: train the interaction surrogate with NMMF.
- al_bench: NMMF against its baselines on the thesis's benchmarks.
- maps: the colour maps of thesis section 4.5.
- campaign: NMMF training with your own CFD as the high fidelity.
- envelope: safe operating envelopes around the submarine.
- validate: physics validation cases and scenario checks.
- bench: benchmarks that print what they measured.
- view: the live map of a running mission, or the replay of a log, in the browser.
- foxglove: a running mission served to Foxglove.
- completion: shell completion scripts.
- moos: nearsub in a MOOS-IvP community (the sim as a MOOS app).
- lf_field: tabulate the low fidelity's submarine field.
- cfd: RANS CFD on OpenFOAM: cases, runs, the SUBOFF validation and its report.
"""
