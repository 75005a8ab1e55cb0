"""A batch of N vehicles stepped once equals N single steps, bit for bit (dynamics.py doc)."""

import numpy as np
import pytest

from nearsub.common.physics.dynamics import Environment, step
from nearsub.common.physics.vehicles import NPS_AUV_II, REMUS100, SDV


@pytest.mark.parametrize("vehicle", [REMUS100, NPS_AUV_II, SDV], ids=lambda v: v.name)
@pytest.mark.parametrize("method", ["euler", "rk4"])
@pytest.mark.parametrize("u_sub", [0.0, 1.5])
def test_batch_step_equals_single_steps_bitwise(vehicle, method, u_sub):
    rng = np.random.default_rng(42)
    n = 17
    states = np.column_stack(
        [
            rng.uniform(0.3, 2.5, n),  # u
            rng.uniform(-0.3, 0.3, n),  # v
            rng.uniform(-0.2, 0.2, n),  # r
            rng.uniform(-50, 50, n),  # x
            rng.uniform(-15, 15, n),  # y
            rng.uniform(-np.pi, np.pi, n),  # psi
        ]
    )
    inputs = np.column_stack(
        [
            rng.uniform(0, vehicle.max_thrust, n),
            rng.uniform(-vehicle.max_rudder, vehicle.max_rudder, n),
        ]
    )
    env = Environment(u_sub=u_sub)
    batch = step(states, inputs, vehicle, env, 0.05, method)
    assert batch.shape == (n, 6)
    for i in range(n):
        single = step(states[i], inputs[i], vehicle, env, 0.05, method)
        assert np.array_equal(batch[i], single)


def test_interaction_forces_replace_only_the_flow_terms():
    from nearsub.common.physics.dynamics import Interaction, body_forces
    from nearsub.common.physics.vehicles import REMUS100 as v

    state = np.array([1.5, 0.1, 0.05, 0.0, 0.0, 0.0])
    inp = np.array([3.0, 0.1])
    plain = body_forces(state, inp, v)
    surrogate = np.array([-2.0, 5.0, -1.0])
    outside = body_forces(state, inp, v, Interaction(surrogate, np.asarray(0.0)))
    inside = body_forces(state, inp, v, Interaction(surrogate, np.asarray(1.0)))
    half = body_forces(state, inp, v, Interaction(surrogate, np.asarray(0.5)))
    np.testing.assert_allclose(outside, plain, rtol=1e-14)
    u, vv, r = state[:3]
    flow = np.array(
        [v.X_uu * u * abs(u), v.Y_vv * vv * abs(vv) + v.Y_uv * u * vv, v.N_vv * vv * abs(vv) + v.N_uv * u * vv]
    )
    np.testing.assert_allclose(inside, plain - flow + surrogate, rtol=1e-12)
    np.testing.assert_allclose(half, 0.5 * (inside + outside), rtol=1e-12)  # linear in the weight: no jump
    increment = body_forces(state, inp, v, Interaction(surrogate, np.asarray(1.0), "increment"))
    np.testing.assert_allclose(increment, plain + surrogate, rtol=1e-12)
    thesis = body_forces(state, inp, v, Interaction(surrogate, np.asarray(1.0), "thesis"))
    control = np.array([inp[0], v.Y_uudr * u * u * inp[1], v.N_uudr * u * u * inp[1]])
    np.testing.assert_allclose(thesis, surrogate + control, rtol=1e-12)  # (5.20) as printed
