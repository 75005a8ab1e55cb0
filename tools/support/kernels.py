"""Every compiled kernel a mission's processes call, compiled into numba's on-disk cache once per
install (tools/run.sh, tools/test.sh) and loaded by the launcher's fork server before it forks the
apps of a mission near a submarine (`launcher.processes.SURROGATE_PRELOAD`)."""

from __future__ import annotations

import numpy as np

from nearsub.common.autonomy import helm
from nearsub.common.hydro import low_fidelity
from nearsub.common.physics.vehicles import LIBRARY


def compile_kernels() -> None:
    """The LF's kernels and the event geometry (`low_fidelity.compile_kernels`), then the helm's
    hull-avoidance prediction (`autonomy.prediction_kernel`) once, for a UUV beside the hull."""
    low_fidelity.compile_kernels()
    situation = helm.Situation(np.array([1.5, 0.0, 0.0, 0.0, 6.5, 0.0]), 0.0, {}, LIBRARY["remus100"], 1.5)
    helm.predicted_clearance(situation, np.zeros(1), np.ones(1), 1.0)


if __name__ == "__main__":
    compile_kernels()
