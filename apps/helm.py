"""The helm app: a thin process shell around `common.mission.cores.HelmCore`."""

from nearsub.apps.shell import main_for
from nearsub.common.mission.cores import HelmCore
from nearsub.common.runtime.processes import leave


def main(argv=None) -> int:
    return main_for(HelmCore, "nearsub helm app", argv)


if __name__ == "__main__":
    leave(main())
