"""`nearsub campaign start|next|tell|export`: an NMMF training campaign whose high fidelity is your CFD.

NMMF (`common/active.py`) asks for samples at two fidelities. Here nearsub answers the low-fidelity
requests itself with its slender-body physics (`hydro_lf`, milliseconds), and hands every
high-fidelity request to the user as a dimensional case (`common/campaign_cases.py`): hulls,
sizes, positions in metres, heading, speed, fluid. The user runs it and records X', Y', N' with
`tell`; the campaign then plans the next case. Everything is saved after every step in the state
file (the campaign's own JSON) and, for a request of several cases (the initial design), the
answers received so far in `<state stem>.answers.json`, so the user can stop at any point.

Case ids are "<request>.<row>", for example 12.1: a stale id (of a request already answered) is
refused. The campaign's problem has its own name, so `nearsub train --resume` refuses to fill it
with panel-method samples. `export` writes the multi-fidelity model and the sample CSVs.
"""

from __future__ import annotations

import json
import os
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np

from ..support.arguments import integer
from ..support.outputs import output_file

DEFAULT_STATE = Path("training") / "cfd-campaign.json"
PROBLEM_NAME = "uuv-submarine-interaction, external HF"


class CampaignError(Exception):
    """A campaign command cannot proceed; the message says why and what to do."""


def _user_hf(X: np.ndarray) -> np.ndarray:
    raise CampaignError("the high fidelity of this campaign is external: answer with `nearsub campaign tell`")


def _problem():
    from nearsub.common.surrogate.training import interaction_problem

    return interaction_problem(
        hf=_user_hf,
        name=PROBLEM_NAME,
        description="HF: the user's simulations (nearsub campaign tell); LF: one-way slender body + ITTC-57",
    )


def _answers_path(state: Path) -> Path:
    return state.with_name(state.stem + ".answers.json")


def _load_answers(state: Path, request_index: int) -> dict[str, list[float]]:
    """Answers recorded so far for the pending request (an older request's answers are stale)."""
    path = _answers_path(state)
    if not path.exists():
        return {}
    saved = json.loads(path.read_text())
    return saved["answers"] if saved.get("request") == request_index else {}


def _save_answers(state: Path, request_index: int, answers: dict[str, list[float]]) -> None:
    path = _answers_path(state)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps({"request": request_index, "answers": answers}))
    os.replace(tmp, path)  # atomic, as the campaign's own state


def _resume(state: Path):
    from nearsub.common.learning.active import Campaign

    if state.is_dir():
        raise CampaignError(f"--state {state}: is a folder; give the campaign file")
    if not state.exists():
        raise CampaignError(f"no campaign at {state}; start one with `nearsub campaign start --state {state}`")
    try:
        return Campaign.resume(state, _problem())
    except (ValueError, KeyError, json.JSONDecodeError) as exc:
        raise CampaignError(f"{state}: not a campaign of `nearsub campaign`: {exc}") from None


def run_low_fidelity(campaign) -> int:
    """Answer the campaign's pending LF requests with the LF physics until it asks for HF (or is
    done); returns the number of LF requests answered."""
    from nearsub.common.hydro import low_fidelity as hydro_lf

    answered = 0
    while (request := campaign.ask()) is not None and request.fidelity == "lf":
        campaign.tell(request.X, hydro_lf.lf_coefficients(request.X))
        answered += 1
    return answered


def pending_cases(campaign, state: Path) -> list[dict[str, Any]]:
    """The HF cases of the pending request not yet answered, with their dimensional geometry."""
    from nearsub.common.surrogate.campaign_cases import case_geometry

    request = campaign.ask()
    if request is None:
        return []
    answers = _load_answers(state, request.index)
    done = len(campaign.data("hf")[0])
    return [
        {"case": f"{request.index}.{k + 1}", "hf_sample": done + k + 1, **case_geometry(row)}
        for k, row in enumerate(request.X)
        if f"{request.index}.{k + 1}" not in answers
    ]


def format_case(case: dict[str, Any], budget: int, state: Path) -> str:
    """A case as text for someone setting up a CFD run."""
    sub, uuv, pos = case["submarine"], case["uuv"], case["position"]
    inputs = " ".join(f"{name}={value:.6g}" for name, value in case["inputs"].items())
    side = "ahead of" if pos["x_m"] >= 0 else "behind"
    return "\n".join(
        [
            f"case {case['case']}  (HF sample {case['hf_sample']} of {budget})",
            f"  submarine  {sub['hull']}",
            f"             length {sub['length_m']:.3f} m, diameter {sub['diameter_m']:.3f} m, "
            f"centre of buoyancy {sub['cb_behind_nose_m']:.3f} m behind its nose",
            f"  UUV        {uuv['hull']}",
            f"             length {uuv['length_m']:.3f} m, diameter {uuv['diameter_m']:.4f} m, "
            f"centre of buoyancy {uuv['cb_behind_nose_m']:.3f} m behind its nose",
            f"  position   UUV centre of buoyancy {abs(pos['x_m']):.3f} m {side} the submarine's centre of buoyancy "
            f"({pos['uuv_cb_behind_submarine_nose_m']:.3f} m behind the submarine's nose) and {pos['y_m']:.3f} m abeam "
            f"of it; hull clearance {pos['clearance_m']:.3f} m",
            f"  heading    {case['heading_deg']:+.3f} deg to the submarine's axis (+ = UUV bow away from it)",
            f"  speed      {case['speed_kn']:.3f} kn = {case['speed_m_s']:.4f} m/s, both vehicles, steady "
            "(in the submarine's frame the stream is -u along its axis)",
            f"  fluid      rho = {case['fluid']['rho_kg_m3']:g} kg/m^3, nu = {case['fluid']['nu_m2_s']:.3g} m^2/s; "
            f"Re_uuv = {case['reynolds_uuv']:.3g}, Re_sub = {case['reynolds_submarine']:.3g}",
            f"  inputs     {inputs}",
            f"  answer     nearsub campaign tell --state {state} --case {case['case']} --X ... --Y ... --N ...",
        ]
    )


def _report(campaign, state: Path, as_json: bool) -> None:
    """Print the pending cases (or that the campaign is complete)."""
    cases = pending_cases(campaign, state)
    if as_json:
        print(json.dumps({"done": campaign.done, "hf_samples": len(campaign.data("hf")[0]), "cases": cases}))
        return
    if campaign.done:
        print(
            f"campaign complete: {len(campaign.data('hf')[0])} HF samples; write the model with "
            f"`nearsub campaign export --state {state} --out MODEL.npz`"
        )
        return
    print("\n\n".join(format_case(case, campaign.settings.hf_budget, state) for case in cases))
    print(f"\nanswers: {cases[0]['answer']}; or with --si, X and Y in N and N in N m")


def start_command(args) -> int:
    from nearsub.common.learning.active import Campaign

    state = output_file(args.state, "--state", parents=True)
    if state.exists() and not args.restart:
        raise CampaignError(f"{state} exists; continue it with `nearsub campaign next` or pass --restart")
    try:
        settings = nmmf_settings(args)
    except ValueError as exc:
        raise CampaignError(f"settings: {exc}") from None
    state.parent.mkdir(parents=True, exist_ok=True)
    _answers_path(state).unlink(missing_ok=True)
    campaign = Campaign(_problem(), settings, path=state)
    run_low_fidelity(campaign)
    print(f"started {state}: NMMF, {args.budget} HF samples, the first {args.n_hf0} as one design", file=sys.stderr)
    _report(campaign, state, args.json)
    return 0


def next_command(args) -> int:
    state = Path(args.state)
    campaign = _resume(state)
    run_low_fidelity(campaign)
    _report(campaign, state, args.json)
    return 0


def _parse_answer(args, request, row: int) -> list[float]:
    """The answer's [X', Y', N'], converted from N and N m with --si; finite or an error."""
    from nearsub.common.physics.hull import uuv_dimensions
    from nearsub.common.surrogate.domain import KNOT, RHO_SEA, to_coefficients

    values = np.array([args.X, args.Y, args.N], dtype=float)
    bad = [f"--{name} {value:g}" for name, value in zip("XYN", values, strict=True) if not np.isfinite(value)]
    if bad:
        raise CampaignError(f"answer must be finite numbers, got {', '.join(bad)}")
    if args.si:
        rho = RHO_SEA if args.rho is None else args.rho
        if not rho > 0:
            raise CampaignError(f"--rho {args.rho!r}: must be a positive density in kg/m^3")
        x = request.X[row]
        _, length = uuv_dimensions(x[4], x[5])
        values = to_coefficients(values, x[2] * KNOT, float(length), rho=rho)[0]
    return values.tolist()


def tell_command(args) -> int:
    state = Path(args.state)
    campaign = _resume(state)
    run_low_fidelity(campaign)
    request = campaign.ask()
    if request is None:
        raise CampaignError(f"{state}: the campaign is complete; nothing is pending")
    ids = [f"{request.index}.{k + 1}" for k in range(len(request.X))]
    answers = _load_answers(state, request.index)
    case = args.case
    if case is None:
        open_ids = [i for i in ids if i not in answers]
        if len(open_ids) != 1:
            raise CampaignError(f"several cases are pending ({', '.join(open_ids)}); name one with --case")
        case = open_ids[0]
    if case not in ids:
        raise CampaignError(f"--case {case}: not pending; the pending cases are {', '.join(ids)}")
    answers[case] = _parse_answer(args, request, ids.index(case))
    if len(answers) < len(ids):
        _save_answers(state, request.index, answers)
        print(f"recorded case {case}; {len(ids) - len(answers)} case(s) of request {request.index} still open")
        return 0
    campaign.tell(request.X, np.array([answers[i] for i in ids]))
    _answers_path(state).unlink(missing_ok=True)
    print(f"recorded case {case}; request {request.index} complete, campaign saved to {state}", file=sys.stderr)
    run_low_fidelity(campaign)
    _report(campaign, state, args.json)
    return 0


def export_command(args) -> int:
    state = Path(args.state)
    campaign = _resume(state)
    if campaign.model is None:
        raise CampaignError(f"{state}: no model yet: the initial HF design is not complete")
    high_fidelity = f"user-supplied simulations recorded with `nearsub campaign tell` ({state})"
    n_hf, n_lf = write_campaign_model(output_file(args.out, "--out", parents=True), campaign, state, high_fidelity)
    status = "complete" if campaign.done else f"in progress, {campaign.settings.hf_budget - n_hf} HF samples to go"
    print(f"wrote {args.out} ({n_hf} HF and {n_lf} LF samples; campaign {status})")
    return 0


def nmmf_settings(args):
    """The thesis's training settings (NMMF, maximum-variance selection (2.31)) with the design
    options of `add_design_arguments`. Raises ValueError for inconsistent sizes."""
    from nearsub.common.learning.active import CampaignSettings

    if args.budget < args.n_hf0:  # the initial HF design is asked for whole, before any budget check
        raise ValueError(f"--budget {args.budget}: smaller than the initial HF design (--n-hf0 {args.n_hf0})")

    return CampaignSettings(
        method="nmmf",
        hf_budget=args.budget,
        selection="max-variance",
        seed=args.seed,
        n_lf0=args.n_lf0,
        n_hf0=args.n_hf0,
    )


def add_design_arguments(p) -> None:
    """--budget, --seed, --n-lf0, --n-hf0: the options `nmmf_settings` reads."""
    p.add_argument(
        "--budget",
        type=integer(minimum=1),
        default=100,
        help="high-fidelity samples in all, the initial design included (default 100, as the thesis)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-lf0", type=integer(minimum=1), default=30, help="initial low-fidelity design")
    p.add_argument(
        "--n-hf0", type=integer(minimum=1), default=10, help="initial high-fidelity design (nested in the LF one)"
    )


def write_campaign_model(out: Path, campaign, state: Path, high_fidelity: str) -> tuple[int, int]:
    """Write a campaign's multi-fidelity model with its provenance, and its samples as CSV beside it
    (<stem>-hf-samples.csv, <stem>-lf-samples.csv); returns the HF and LF sample counts."""
    from datetime import UTC, datetime

    from nearsub.common.surrogate import model as sg
    from nearsub.common.surrogate.training import write_samples

    from .train import command_line

    out.parent.mkdir(parents=True, exist_ok=True)
    X_hf, Y_hf = campaign.data("hf")
    X_lf, Y_lf = campaign.data("lf")
    provenance = {
        "method": "NMMF active learning (thesis Algorithm 1), maximum-variance multi-output selection (2.31); "
        "Kennedy-O'Hagan multi-fidelity GP with rho = 1",
        "high_fidelity": high_fidelity,
        "low_fidelity": "nearsub one-way slender-body model with ITTC-57 friction (common/hydro/low_fidelity.py)",
        "command": command_line("nearsub campaign export"),
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "hf_samples": int(len(X_hf)),
        "lf_samples": int(len(X_lf)),
        "campaign": str(state),
        "settings": json.loads(json.dumps(campaign.settings.__dict__)),
    }
    sg.save_surrogate(out, campaign.model, provenance)
    write_samples(out.with_name(out.stem + "-hf-samples.csv"), X_hf, Y_hf)
    write_samples(out.with_name(out.stem + "-lf-samples.csv"), X_lf, Y_lf)
    return len(X_hf), len(X_lf)


def campaign_command(args) -> int:
    commands = {"start": start_command, "next": next_command, "tell": tell_command, "export": export_command}
    try:
        return commands[args.campaign_command](args)
    except CampaignError as exc:
        print(f"nearsub campaign {args.campaign_command}: {exc}", file=sys.stderr)
        return 2


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("campaign", help="NMMF training with your own CFD as the high fidelity")
    sub = p.add_subparsers(dest="campaign_command", required=True)

    def with_state(t):
        t.add_argument("--state", default=str(DEFAULT_STATE), help=f"campaign file (default {DEFAULT_STATE})")
        return t

    t = with_state(sub.add_parser("start", help="start a campaign and print its first HF cases"))
    add_design_arguments(t)
    t.add_argument("--restart", action="store_true", help="replace an existing campaign file")
    t.add_argument("--json", action="store_true")
    t = with_state(sub.add_parser("next", help="print the pending HF case(s) as dimensional geometry"))
    t.add_argument("--json", action="store_true")
    t = with_state(sub.add_parser("tell", help="record the answer of one HF case"))
    # argparse (3.11) reads a value like -1.2e-3 as an option; widen its negative-number pattern (an
    # attribute of the parser) so coefficients in exponent notation pass as values.
    t._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
    t.add_argument("--case", help="case id as printed by next, e.g. 12.1 (optional when one case is pending)")
    t.add_argument("--X", type=float, required=True, help="X' (or X in N with --si)")
    t.add_argument("--Y", type=float, required=True, help="Y' (or Y in N with --si)")
    t.add_argument("--N", type=float, required=True, help="N' (or N in N m with --si)")
    t.add_argument("--si", action="store_true", help="the answer is in N and N m; convert with --rho")
    t.add_argument("--rho", type=float, help="water density for --si [kg/m^3] (default: sea water, 1025)")
    t.add_argument("--json", action="store_true")
    t = with_state(sub.add_parser("export", help="write the campaign's model file and sample CSVs"))
    t.add_argument("--out", required=True, help="model file to write (.npz)")
    p.set_defaults(func=campaign_command)
