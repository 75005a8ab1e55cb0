"""Every message of three scenario missions: the interaction's speed-ups (single-row paths, compiled
kernels) must not move the forces, states, decisions or events.

- On this machine, bit for bit: the mission launched as processes equals the in-process run, every
  message of every topic (the forces' std to STD_RTOL: the surrogate server's GP rows go through
  another BLAS product, `gp._Predictor.rows`).
- Across machines, with tolerances: the in-process run's `helpers.mission_trace` (message counts,
  every event, sampled messages of every topic) against tests/data/message-traces.json, pinned on
  any CPU by `python tests/pin_message_digests.py NAME...` after a deliberate change of the
  physics; floats to TRACE_ATOL + TRACE_RTOL |x| (helpers: a CPU's last-bit differences stay below
  1e-11 N in the forces, a real change far above).
"""

import json
from collections import defaultdict
from functools import cache

import numpy as np
import pytest
from test_reliability import run_budget

from conftest import ROOT
from helpers import log_path, mission_trace, per_topic, trace_differences
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.messages import Forces, decode, encode

PINS = ROOT / "tests" / "data" / "message-traces.json"
# An N_uv-compensated overtake (the sim's and the helm's interaction every step), hull avoidance
# near midships (the helm's own forces), a REMUS 100 (hull ratios outside table 4.2, clipped).
MISSIONS = ["overtake_stern_nuv", "recovery", "lateral_approach"]
STD_FIELDS = ("std_X", "std_Y", "std_N")
STD_RTOL = 1e-9


@cache
def in_process(name: str):
    """The mission run in-process, once per test session (its name changes none of its messages)."""
    return run_mission(load_mission(ROOT / "missions" / f"{name}.toml"))


def message_trace(name: str) -> dict:
    """What tests/data/message-traces.json pins of a mission: its `mission_trace`, every topic."""
    return mission_trace(in_process(name))


@pytest.mark.slow
@pytest.mark.timeout(1200)
@pytest.mark.parametrize("name", MISSIONS)
def test_every_message_of_the_scenario_missions_matches_the_pinned_trace(name):
    assert trace_differences(message_trace(name), json.loads(PINS.read_text())[name]) == []


@pytest.mark.slow
@pytest.mark.timeout(1200)
@pytest.mark.parametrize("name", MISSIONS)
def test_every_message_of_the_scenario_missions_as_processes_equals_in_process(name, launches, community):
    path = ROOT / "missions" / f"{name}.toml"
    mission = load_mission(path, [f"name={community}"])
    code, summary, err = launches.run(path, "--set", f"name={community}", timeout=run_budget(mission))
    assert code == 0, err
    reference = in_process(name)
    expected = defaultdict(list)
    for app, topic, message in reference.messages:
        key = f"events/{app}-1" if topic == "events" else f"{mission.vehicle_name}/{topic}"
        expected[key].append(message)
    logged = per_topic(log_path(summary))
    assert {key for key in logged if not key.startswith("clock/")} == expected.keys()  # the clock's is no app's
    for key, messages in expected.items():
        if not key.endswith("/forces"):
            assert logged[key] == [encode(m) for m in messages], key
            continue
        assert len(logged[key]) == len(messages)
        for raw, message in zip(logged[key], messages, strict=True):
            launched = decode(raw, Forces)
            # Bit for bit apart from the std (encoded, so that a NaN, delta not asked, equals itself).
            assert encode(launched.model_copy(update=dict.fromkeys(STD_FIELDS, 0.0))) == encode(
                message.model_copy(update=dict.fromkeys(STD_FIELDS, 0.0))
            ), message.step
            stds = [[getattr(m, field) for field in STD_FIELDS] for m in (launched, message)]
            np.testing.assert_allclose(*stds, rtol=STD_RTOL, atol=0)  # NaN where not asked, in both
