"""`nearsub lf-field [-o FILE]`: tabulate the low fidelity's submarine field (the ring-panel
velocities at every node of its table) into the file the package ships as
`nearsub/data/lf-field.npz`, so no process computes it at start-up. Rerun it, and copy the file
over the shipped one, after a change to the ring-panel solution, the hull or the table's grid
(then also bump `LF_VERSION`); tests/test_hydro_cache.py checks the shipped file.
"""

from __future__ import annotations

from pathlib import Path


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("lf-field", help="tabulate the LF's submarine field (the shipped table)")
    p.add_argument(
        "-o",
        "--out",
        type=Path,
        default=Path("lf-field.npz"),
        help="output file, .npz added to another name (default ./lf-field.npz)",
    )
    p.set_defaults(func=lf_field_command)


def lf_field_command(args) -> int:
    import numpy as np

    from nearsub.common.hydro import low_fidelity

    from ..support.outputs import numpy_file, output_file

    out = output_file(numpy_file(args.out))  # numpy adds .npz to another name: check and name that file
    table = low_fidelity.tabulate_field()
    np.savez_compressed(out, **table)
    print(f"wrote {out}: {table['x'].size} x {table['r'].size} nodes, LF version {int(table['lf_version'])}")
    return 0
