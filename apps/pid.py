"""The pid app: a thin process shell around `common.mission.cores.PidCore`."""

from nearsub.apps.shell import main_for
from nearsub.common.mission.cores import PidCore
from nearsub.common.runtime.processes import leave


def main(argv=None) -> int:
    return main_for(lambda mission, surrogate: PidCore(mission), "nearsub pid app", argv)


if __name__ == "__main__":
    leave(main())
