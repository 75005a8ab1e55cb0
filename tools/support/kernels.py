"""Every compiled kernel a mission's processes call, compiled into numba's on-disk cache once per
install (tools/run.sh, tools/test.sh) and loaded by the launcher's fork server before it forks the
apps of a mission near a submarine (`launcher.processes.SURROGATE_PRELOAD`)."""

from __future__ import annotations

import numpy as np

from nearsub.common.autonomy import helm
from nearsub.common.hydro import low_fidelity
from nearsub.common.physics.vehicles import LIBRARY
from nearsub.common.surrogate import domain, interaction


def compile_kernels() -> None:
    """The LF's kernels and the event geometry (`low_fidelity.compile_kernels`), the domain's
    (`surrogate.interaction_kernel`, every entry), then the helm's hull-avoidance prediction
    (`autonomy.prediction_kernel`) once, for a UUV beside the hull."""
    low_fidelity.compile_kernels()
    inputs, mirror = domain.to_inputs(0.0, 6.5, 1.5, 0.0, 1.6, 0.19)
    domain.to_forces(domain.constraint_values(inputs)[:, :3], mirror, 1.5, 1.6)
    for lf_in_loop in (True, False):
        interaction.DomainRows.of(inputs, lf_in_loop)
    interaction.blend_weight(inputs), interaction.discrepancy_weight(inputs), interaction.discrepancy_inputs(inputs)
    interaction.outside_mask(inputs), interaction.lf_reach_weight(np.zeros(1), np.full(1, 6.5))
    situation = helm.Situation(np.array([1.5, 0.0, 0.0, 0.0, 6.5, 0.0]), 0.0, {}, LIBRARY["remus100"], 1.5)
    helm.predicted_clearance(situation, np.zeros(1), np.ones(1), 1.0)


if __name__ == "__main__":
    compile_kernels()
