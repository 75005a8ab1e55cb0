"""Every message of three scenario missions, bit for bit: the interaction's speed-ups (single-row
paths, compiled kernels) must not move a single bit of the forces, states, decisions or events.
`python tests/pin_message_digests.py NAME...` re-pins tests/data/message-digests.json after a
deliberate change of the physics."""

import hashlib
import json

import pytest

from conftest import ROOT
from nearsub.common.mission.cores import run_mission
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.messages import encode

PINS = ROOT / "tests" / "data" / "message-digests.json"
# An N_uv-compensated overtake (the sim's and the helm's interaction every step), hull avoidance
# near midships (the helm's own forces), a REMUS 100 (hull ratios outside table 4.2, clipped).
MISSIONS = ["overtake_stern_nuv", "recovery", "lateral_approach"]


def message_digests(name: str) -> dict:
    """The SHA-256 of each message's wire bytes (app, topic and `messages.encode`), in publishing
    order, chained into one digest, with their count and how the run ended."""
    result = run_mission(load_mission(ROOT / "missions" / f"{name}.toml"))
    chained = hashlib.sha256()
    for app, topic, message in result.messages:
        chained.update(hashlib.sha256(f"{app}|{topic}|".encode() + encode(message)).digest())
    return {"n": len(result.messages), "sha256": chained.hexdigest(), "outcome": result.outcome, "steps": result.steps}


@pytest.mark.slow
@pytest.mark.timeout(1200)
@pytest.mark.parametrize("name", MISSIONS)
def test_every_message_of_the_scenario_missions_keeps_its_bits(name):
    assert message_digests(name) == json.loads(PINS.read_text())[name]
