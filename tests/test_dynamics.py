"""A batch of N vehicles stepped once equals N single steps, bit for bit (dynamics.py doc)."""

import numpy as np
import pytest

from nearsub.common.dynamics import Environment, step
from nearsub.common.vehicles import NPS_AUV_II, REMUS100, SDV


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
