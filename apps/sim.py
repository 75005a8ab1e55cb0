"""The sim app: a thin process shell around `common.mission.cores.SimCore`.

With `apps.sim.surrogate = "in_process"` the sim loads the mission's surrogate model itself
instead of asking the surrogate server every step (docs/architecture.md, "Where the sim
evaluates the surrogate"): the same `Surrogate` class and file as the in-process run, so the
same forces to the bit, without the round trip."""

from nearsub.apps.entry import AppError
from nearsub.apps.shell import main_for
from nearsub.common.mission.cores import SimCore, mission_surrogate, sim_forces
from nearsub.common.mission.schema import Mission
from nearsub.common.runtime.processes import leave


def sim_core(mission: Mission, server) -> SimCore:
    """The core, with the surrogate server's client `server` or, in "in_process" mode, the model."""
    if mission.apps.sim.surrogate == "in_process" and sim_forces(mission):
        from nearsub.common.surrogate.modelfile import ModelFileError

        try:
            return SimCore(mission, mission_surrogate(mission))
        except ModelFileError as exc:
            raise AppError(f"surrogate.model: {exc}", 2) from None
    return SimCore(mission, server)


def main(argv=None) -> int:
    return main_for(sim_core, "nearsub sim app", argv)


if __name__ == "__main__":
    leave(main())
