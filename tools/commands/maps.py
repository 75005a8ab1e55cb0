"""`nearsub maps [MODEL] [-o DIR]`: the colour maps of thesis section 4.5 as PNGs, by default into
./maps (the shipped ones are regenerated with `-o docs/maps`).

One PNG per thesis figure (4-4, 4-5, 4-7, 4-8, 4-9, 4-10, 4-11), drawn by `map_figures`.
Figures 4-9 to 4-11 compare the model with its low-fidelity GP, so they need a multi-fidelity
model file; for a single-fidelity one they are skipped.
"""

from __future__ import annotations

import sys
from pathlib import Path

DEFAULT_OUT = Path("maps")  # in the working directory, never over the shipped docs/maps


def maps_command(args) -> int:
    from nearsub.common.surrogate.maps import THESIS_MAPS, has_low_fidelity
    from nearsub.common.surrogate.model import load_surrogate
    from nearsub.common.surrogate.modelfile import ModelFileError

    from ..map_figures import plot_figure
    from ..support.outputs import output_folder

    out_dir = output_folder(args.out, "--out")
    try:
        surrogate = load_surrogate(args.model)
    except ModelFileError as exc:
        print(f"nearsub maps: {exc}", file=sys.stderr)
        return 2
    multi_fidelity = has_low_fidelity(surrogate.model)
    for name, panels in THESIS_MAPS.items():
        if not multi_fidelity and any(p.fidelity == "lf" for p in panels):
            print(f"skipped {name}: it compares with the low-fidelity surrogate, and {surrogate.source} has none")
            continue
        print(f"wrote {plot_figure(surrogate, name, out_dir)}")
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("maps")
    p.add_argument("model", nargs="?", help="model file (default: the shipped model)")
    p.add_argument("-o", "--out", default=str(DEFAULT_OUT), help=f"folder for the PNGs (default ./{DEFAULT_OUT})")
    p.set_defaults(func=maps_command)
