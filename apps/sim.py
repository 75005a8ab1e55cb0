"""The sim app: a thin process shell around `common.mission.cores.SimCore`."""

from nearsub.apps.shell import main_for
from nearsub.common.mission.cores import SimCore
from nearsub.common.runtime.processes import leave


def main(argv=None) -> int:
    return main_for(SimCore, "nearsub sim app", argv)


if __name__ == "__main__":
    leave(main())
