"""`nearsub train`: train the interaction surrogate with NMMF active learning (thesis ch. 2 and 4).

The two fidelities are nearsub's own physics (SPEC section 7): the low fidelity is the one-way
slender-body model (`common/hydro_lf.py`), the high fidelity the two-way panel model
(`common/hydro_hf.py`). NMMF (`common/active.py`) picks every sample, with maximum-variance
selection over the three outputs (2.31). The campaign saves itself after every sample, so a killed
run resumes with `--resume` without repeating or losing one. At the end the multi-fidelity model
is written as a model file with its provenance, and the samples as CSV.
"""

from __future__ import annotations

import csv
import json
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from nearsub.common import hydro_hf, hydro_lf
from nearsub.common import surrogate as sg
from nearsub.common.active import Campaign, CampaignSettings
from nearsub.common.testproblems import Problem

DEFAULT_STATE = Path("training") / "campaign.json"


def interaction_problem() -> Problem:
    """The surrogate's domain (table 4.2, constraints (4.4)-(4.7)) with the two physics fidelities."""
    return Problem(
        name="uuv-submarine-interaction",
        bounds=sg.BOUNDS,
        input_names=sg.INPUT_NAMES,
        output_names=sg.OUTPUT_NAMES,
        hf=hydro_hf.hf_coefficients,
        lf=hydro_lf.lf_coefficients,
        constraint=sg.constraint_values,
        description="HF: two-way Hess-Smith panels with viscous corrections; LF: one-way slender body + ITTC-57",
    )


def write_samples(path: Path, X: np.ndarray, Y: np.ndarray) -> None:
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow([*sg.INPUT_NAMES, *sg.OUTPUT_NAMES])
        writer.writerows(np.column_stack([X, Y]).tolist())


def train_command(args) -> int:
    problem = interaction_problem()
    state = Path(args.state)
    if args.resume:
        if not state.exists():
            print(f"nearsub train: no campaign to resume at {state}", file=sys.stderr)
            return 2
        campaign = Campaign.resume(state, problem)
    else:
        if state.exists() and not args.restart:
            print(f"nearsub train: {state} exists; pass --resume to continue it or --restart", file=sys.stderr)
            return 2
        state.parent.mkdir(parents=True, exist_ok=True)
        settings = CampaignSettings(
            method="nmmf",
            hf_budget=args.budget,
            selection="max-variance",
            seed=args.seed,
            n_lf0=args.n_lf0,
            n_hf0=args.n_hf0,
        )
        campaign = Campaign(problem, settings, path=state)
    started = time.perf_counter()
    hf_seconds = 0.0
    columns = (
        TextColumn("[bold]HF samples"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TextColumn("{task.fields[error]}"),
        TimeRemainingColumn(),
    )
    with Progress(*columns, disable=not sys.stderr.isatty() and not args.progress) as progress:
        task = progress.add_task("train", total=campaign.settings.hf_budget, completed=campaign.n_hf, error="")
        while (request := campaign.ask()) is not None:
            began = time.perf_counter()
            Y = (problem.lf if request.fidelity == "lf" else problem.hf)(request.X)
            if request.fidelity == "hf":
                hf_seconds += time.perf_counter() - began
            campaign.tell(request.X, Y)
            if campaign.model is not None:
                probe = sg.sample_feasible(200, seed=1)
                _, std = campaign.model.predict(probe, return_std=True)
                progress.update(task, completed=campaign.n_hf, error=f"mean predicted std {np.mean(std):.2e}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    X_hf, Y_hf = campaign.data("hf")
    X_lf, Y_lf = campaign.data("lf")
    provenance = {
        "method": "NMMF active learning (thesis Algorithm 1), maximum-variance multi-output selection (2.31); "
        "Kennedy-O'Hagan multi-fidelity GP with rho = 1",
        "high_fidelity": "nearsub two-way Hess-Smith panel method with viscous corrections (common/hydro_hf.py); "
        "NOT RANS CFD (docs/hydro/README.md)",
        "low_fidelity": "nearsub one-way slender-body model with ITTC-57 friction (common/hydro_lf.py)",
        "command": "nearsub " + " ".join(sys.argv[1:]) if sys.argv and "nearsub" in sys.argv[0] else "nearsub train",
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "hf_samples": int(len(X_hf)),
        "lf_samples": int(len(X_lf)),
        "campaign": str(state),
        "settings": json.loads(json.dumps(campaign.settings.__dict__)),
    }
    sg.save_surrogate(out, campaign.model, provenance)
    write_samples(out.with_name(out.stem + "-hf-samples.csv"), X_hf, Y_hf)
    write_samples(out.with_name(out.stem + "-lf-samples.csv"), X_lf, Y_lf)
    elapsed = time.perf_counter() - started
    print(
        f"wrote {out} ({len(X_hf)} HF and {len(X_lf)} LF samples) in {elapsed / 3600:.2f} h; HF runs {hf_seconds:.0f} s"
    )
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("train", help="train the interaction surrogate with NMMF (LF + HF physics)")
    p.add_argument("--budget", type=int, default=100, help="high-fidelity samples (default 100, as the thesis)")
    p.add_argument("--state", default=str(DEFAULT_STATE), help="campaign file, saved after every sample")
    p.add_argument("--resume", action="store_true", help="continue the campaign in --state")
    p.add_argument("--restart", action="store_true", help="start over even if --state exists")
    p.add_argument("--out", default=str(sg.default_model_path()), help="model file to write (default: the shipped one)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-lf0", type=int, default=30, help="initial low-fidelity design")
    p.add_argument("--n-hf0", type=int, default=10, help="initial high-fidelity design (nested in the LF one)")
    p.add_argument("--progress", action="store_true", help="show the progress bar even when not on a terminal")
    p.set_defaults(func=train_command)
