"""Build the free-stream table of a surrogate model for the "increment" interaction mode.

    python -m nearsub.tools.free_stream [MODEL] [--panels medium] [--grid 9 9 7] [--out PATH]

MODEL defaults to the shipped surrogate, and the table goes next to the model as
`<stem>-free-stream.npz` (for the shipped model: nearsub/data/surrogate-free-stream.npz). The table
is the free stream of the high-fidelity panel model (common/hydro/high_fidelity.py), so the model must have
been trained on it: a model whose provenance names another high fidelity (a user's CFD, the
analytic test fixture) is refused unless --force. Takes a few seconds (common/surrogate/free_stream.py).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from nearsub.common.runtime.processes import single_blas_thread

single_blas_thread()  # before numpy loads

from nearsub.common.hydro import high_fidelity as hydro_hf  # noqa: E402
from nearsub.common.surrogate import free_stream as fs  # noqa: E402
from nearsub.common.surrogate.model import default_model_path, load_surrogate  # noqa: E402
from nearsub.common.surrogate.modelfile import ModelFileError  # noqa: E402

PANELS = {"coarse": hydro_hf.COARSE, "medium": hydro_hf.MEDIUM, "fine": hydro_hf.FINE}
HF_MARK = "common/hydro_hf.py"  # what `nearsub train` writes into a model's provenance["high_fidelity"]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m nearsub.tools.free_stream", description=__doc__.split("\n")[0])
    parser.add_argument("model", nargs="?", help="surrogate model file (default: the shipped model)")
    parser.add_argument("--panels", choices=sorted(PANELS), default="medium", help="HF mesh (train uses medium)")
    parser.add_argument("--grid", type=int, nargs=3, default=list(fs.GRID), metavar=("N_LD", "N_PSI", "N_RE"))
    parser.add_argument("--out", help="output file (default: next to the model, <stem>-free-stream.npz)")
    parser.add_argument("--force", action="store_true", help="build even if the model was not trained on hydro_hf")
    args = parser.parse_args(argv)
    if min(args.grid) < 4:
        parser.error("--grid needs at least 4 points per axis (cubic interpolation)")
    model_path = Path(args.model) if args.model else default_model_path()
    try:
        surrogate = load_surrogate(model_path)
    except (OSError, ModelFileError) as exc:
        print(f"free_stream: {exc}", file=sys.stderr)
        return 2
    high_fidelity = str(surrogate.loaded.provenance.get("high_fidelity", ""))
    if HF_MARK not in high_fidelity and not args.force:
        print(
            f"free_stream: {model_path} was not trained on {HF_MARK} (its provenance says high_fidelity = "
            f"{high_fidelity!r}), so the panel model's free stream is not its free stream; --force to build anyway",
            file=sys.stderr,
        )
        return 2
    out = Path(args.out) if args.out else fs.table_path_for(model_path)
    command = "python -m nearsub.tools.free_stream " + " ".join(argv if argv is not None else sys.argv[1:])
    table = fs.build_table(
        PANELS[args.panels],
        tuple(args.grid),
        surrogate_model_id=surrogate.model_id,
        surrogate_model=model_path.name,
        command=command.strip(),
    )
    fs.save_table(out, table)
    check = table.provenance["check"]
    print(
        f"wrote {out}: {' x '.join(str(n) for n in args.grid)} points, {args.panels} panels, "
        f"built in {table.provenance['build_seconds']} s, for model {surrogate.model_id}; "
        f"max error at {check['points']} off-grid points [X', Y', N'] = "
        + ", ".join(f"{e:.2g}" for e in check["max_abs_error"])
        + " (largest values "
        + ", ".join(f"{v:.2g}" for v in check["max_abs_value"])
        + ")"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
