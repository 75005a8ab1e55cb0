"""The `nearsub` command line: `cli` dispatches to one module per subcommand (listed in `cli.TOOLS`).

Beside them: the `launcher` package runs and supervises a launched mission's processes, `connect`
and `registry` find a running mission, `caller` sends control requests, `errors` is the bad-input error `cli` prints, `plot` and
`map_figures` draw, `hydro_bench` measures the hydrodynamic fidelities, `free_stream` builds a
model's free-stream table (`python -m`).
"""
