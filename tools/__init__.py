"""The `nearsub` command: `cli` parses the command line and runs one subcommand.

- cli: the program; `cli.TOOLS` lists the subcommands and the module of each.
- commands/: one module per subcommand (`commands/log.py` is `nearsub log`).
- support/: what the subcommands share (arguments, outputs, errors, tables, registry, connect,
  caller, schedulers, log input).
- launcher/: the launch of a mission as processes (`nearsub launch`, `nearsub bench`, the tests).
- What one subcommand draws, measures or serves: logplay and plot (`log play`, `log plot`),
  view_server (`view`), helm_bench, hydro_bench and moos_alpha (`bench`), map_figures (`maps`),
  sweep_figures (`surrogate sweep`).
- Scripts run with `python -m`: free_stream (a model's free-stream table), fleet_figure (a fleet
  mission's figure).
"""
