"""`nearsub moos sim FILE.moos [NAME]`: nearsub's sim in a MOOS community, as uSimMarineV22
(docs/moos.md). pAntler starts it with `InhibitMOOSParams = true` and the arguments in
`ExtraProcessParams` (missions/moos/). Needs the `moos` extra (pymoos2, the MOOSDB client)."""

from __future__ import annotations

import sys


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("moos", help="nearsub in a MOOS-IvP community (needs the moos extra)")
    sub = p.add_subparsers(dest="moos_command", required=True, metavar="ACTION")
    sim = sub.add_parser("sim", help="the sim as a MOOS app: DESIRED_* in, NAV_* out (uSimMarineV22)")
    sim.add_argument("moos_file", help="the community's .moos file, with a ProcessConfig block for the sim")
    sim.add_argument("name", nargs="?", default="nearsub_sim", help="its MOOS name and ProcessConfig block")
    sim.set_defaults(func=sim_command)


def sim_command(args) -> int:
    from nearsub.apps.entry import AppError
    from nearsub.apps.moos_sim import missing_client, run
    from nearsub.common.mission.cores import mission_surrogate
    from nearsub.common.mission.schema import MissionError
    from nearsub.common.moos.config import MoosConfigError, read_moos, sim_config
    from nearsub.common.moos.sim import sim_mission

    if problem := missing_client():
        print(f"nearsub moos: {problem}", file=sys.stderr)
        return 2
    try:
        config = sim_config(read_moos(args.moos_file), args.name)
        mission = sim_mission(config)
        surrogate = mission_surrogate(mission) if mission.needs_surrogate else None
    except (MoosConfigError, MissionError) as exc:
        print(f"nearsub moos sim: {exc}", file=sys.stderr)
        return 2
    try:
        return run(config, mission, args.name, surrogate)
    except AppError as exc:
        print(f"nearsub moos sim: {exc}", file=sys.stderr)
        return exc.code
