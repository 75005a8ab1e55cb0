"""The helm's compiled hull-avoidance prediction against the numpy dynamics and PID it stands for."""

import math

import numpy as np
import pytest

from nearsub.common.autonomy import control, helm, prediction_kernel
from nearsub.common.physics import dynamics, proximity
from nearsub.common.physics.vehicles import LIBRARY

MODES = (None, "increment", "replace", "thesis")


def numpy_poses(s: helm.Situation, psi_c, u_c, steps: int) -> np.ndarray:
    """Every candidate flown with `control.pid_step` and `dynamics.step` on (n,) arrays, the
    poses at the helm's check steps: what the kernel must reproduce."""
    v = s.vehicle
    x = np.repeat(s.state[None, :], len(psi_c), axis=0)
    memory = control.PidState.zeros((len(psi_c),))
    held = None
    if s.interaction is not None:
        f = s.interaction
        held = dynamics.Interaction(
            np.broadcast_to(f.forces, x.shape[:1] + (3,)), np.broadcast_to(f.weight, x.shape[:1]), f.mode
        )
    poses = []
    with np.errstate(all="ignore"):
        for k in range(1, steps + 1):
            memory, out = control.pid_step(memory, u_c, psi_c, x, v, v.pid, helm.AVOID_DT)
            command = np.stack([out.thrust, out.rudder], axis=-1)
            x = dynamics.step(x, command, v, dynamics.Environment(s.u_sub), helm.AVOID_DT, "euler", 0.0, held)
            if k % helm.AVOID_CHECK == 0 or k == steps:
                poses.append(
                    np.column_stack(
                        [x[:, dynamics.X], x[:, dynamics.Y], x[:, dynamics.PSI], np.isfinite(x).all(axis=1)]
                    )
                )
    return np.stack(poses, axis=1)


def kernel_poses(s: helm.Situation, psi_c, u_c, steps: int) -> np.ndarray:
    checks = math.ceil(steps / helm.AVOID_CHECK)
    poses = np.empty((len(psi_c), checks, 4))
    f = s.interaction
    forces, weight, mode = (
        (np.zeros(3), 0.0, None) if f is None else (np.asarray(f.forces, float), float(f.weight), f.mode)
    )
    prediction_kernel.flown_poses(
        s.state, psi_c, u_c, prediction_kernel.vehicle_row(s.vehicle), forces, weight,
        prediction_kernel.MODE_CODES[mode], s.u_sub, helm.AVOID_DT, steps, helm.AVOID_CHECK, poses,
    )  # fmt: skip
    return poses


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_the_compiled_prediction_flies_the_numpy_dynamics_and_pid(name, mode):
    """Same poses to rounding (the C library's cos and sin against numpy's, carried over 31
    Euler steps): 1e-9 m and rad, for every library vehicle, every interaction mode, an odd
    number of steps (the last one checked too) and states turning, drifting and slow."""
    vehicle = LIBRARY[name]
    rng = np.random.default_rng(sum(map(ord, name + str(mode))))
    for _ in range(3):
        state = np.array(
            [
                rng.uniform(0.3, 2.0),
                rng.uniform(-0.3, 0.3),
                rng.uniform(-0.3, 0.3),
                rng.uniform(-40, 40),
                rng.uniform(5.5, 12),
                rng.uniform(-3, 3),
            ]
        )
        interaction = None
        if mode is not None:
            scale = vehicle.mass * 0.05
            interaction = dynamics.Interaction(
                rng.normal(0, scale, 3) * [1, 1, vehicle.length], np.array(rng.uniform(0, 1)), mode
            )
        s = helm.Situation(state, 0.0, {}, vehicle, 1.5, interaction=interaction)
        headings = dynamics.wrap_angle(state[dynamics.PSI] + helm.AVOID_OFFSETS)
        psi_c, u_c = (
            a.ravel()
            for a in np.meshgrid(headings, helm.AVOID_SPEED_FRACTIONS * helm.top_speed(vehicle), indexing="ij")
        )
        expected = numpy_poses(s, psi_c, u_c, 31)
        got = kernel_poses(s, psi_c, u_c, 31)
        np.testing.assert_array_equal(got[..., 3], expected[..., 3])
        np.testing.assert_allclose(got[..., :3], expected[..., :3], rtol=0, atol=1e-9)


def test_predicted_clearance_reads_the_poses_outline_and_counts_divergence_as_collision():
    """The clearance is the least outline distance over the check poses; a prediction whose state
    stops being finite counts as a collision (-inf)."""
    vehicle = LIBRARY["remus100"]
    s = helm.Situation(np.array([1.5, 0.0, 0.0, -3.44, 6.5, 0.0]), 0.0, {}, vehicle, 1.5)
    psi_c, u_c = np.array([0.0, -1.0]), np.array([1.5, 2.0])
    steps = math.ceil(3.0 / helm.AVOID_DT - 1e-9)
    poses = numpy_poses(s, psi_c, u_c, steps)
    bx, by = helm._outline(vehicle.length, vehicle.diameter)
    c, sn = np.cos(poses[..., 2, None]), np.sin(poses[..., 2, None])
    px, py = poses[..., 0, None] + bx * c - by * sn, poses[..., 1, None] + bx * sn + by * c
    expected = proximity.hull_signed_distance(px, py).min(axis=-1).min(axis=-1)
    got = helm.predicted_clearance(s, psi_c, u_c, 3.0)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
    assert got[1] < got[0]  # turning in towards the hull comes closer
    blown = dynamics.Interaction(np.array([[0.0, 1e300, 1e300]]), np.array([1.0]), "increment")  # the sim's one row
    assert np.all(
        helm.predicted_clearance(helm.Situation(s.state, 0.0, {}, vehicle, 1.5, interaction=blown), psi_c, u_c, 3.0)
        == -np.inf
    )
