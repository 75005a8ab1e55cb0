"""Envelope cells flown as missions through the multi-process launcher end exactly as the batch
engine says: same outcome, same final state (to 1e-9; the arithmetic is the same, only zero
forces outside the surrogate's domain may differ in the sign of a zero)."""

import numpy as np
import pytest

from nearsub.common.analysis import envelope as env
from nearsub.common.analysis.batch import OUTCOMES
from nearsub.common.autonomy.behaviours import track_geometry
from nearsub.common.physics.proximity import STRAY_LIMIT
from nearsub.common.runtime.logfile import read_log

pytestmark = pytest.mark.timeout(600)

# A large UUV close to the hull, 30 s per cell: the batch finds all four outcomes in it.
CONFIG = env.EnvelopeConfig(vehicle="sdv", grid=(9, 4), r_long=(-0.6, 0.6), r_lat=(0.0585, 0.07), duration=30.0)


def pick_cells(found: env.Envelope) -> list[int]:
    """The first cell of each outcome, then more feasible cells up to six."""
    outcome = found.result.outcome
    chosen = [int(np.flatnonzero(outcome == code)[0]) for code in range(4) if (outcome == code).any()]
    for k in np.flatnonzero(outcome != OUTCOMES.index("infeasible")):
        if len(chosen) >= 6:
            break
        if k not in chosen:
            chosen.append(int(k))
    return chosen


def mission_outcome(summary: dict, states: np.ndarray, start: tuple[float, float]) -> str:
    """A mission's envelope outcome, by the same priority: the sim's collision and close-call
    events, and a large stray from the logged states, every step, as the batch measures it."""
    if summary["outcome"] == "collision":
        return "collision"
    if summary["events"].get("close_call", 0):
        return "close_call"
    track_start, track_end = np.array(start), np.array([start[0] + env.TRACK_AHEAD, start[1]])
    cross = np.abs(track_geometry(track_start, track_end, states[:, 3:5])[3])
    return "large_stray" if cross.max() > STRAY_LIMIT else "safe"


def logged_states(log: str) -> np.ndarray:
    rows = []
    for record in read_log(log).records:
        if record.topic.endswith("/state") and "#" not in record.topic:
            value = record.value()
            rows.append([value[k] for k in ("u", "v", "r", "x", "y", "psi")])
    return np.array(rows)


def test_envelope_cells_through_the_launcher_match_the_batch(launches, community, tmp_path):
    found = env.compute_envelope(CONFIG)
    cells = pick_cells(found)
    names = [OUTCOMES[found.result.outcome[k]] for k in cells]
    assert len(cells) >= 5 and {"collision", "safe"} <= set(names), names
    x, y = env.cell_positions(CONFIG)
    for k in cells:
        path = tmp_path / f"cell{k}.toml"
        path.write_text(env.mission_toml(env.mission_data(CONFIG, float(x[k]), float(y[k]), f"{community}c{k}")))
        code, summary, err = launches.run(path, timeout=300)
        assert code == 0, err
        states = logged_states(summary["log"])
        assert summary["steps"] == found.result.steps[k]
        np.testing.assert_allclose(states[-1], found.result.final[k], rtol=0, atol=1e-9, err_msg=f"cell {k}")
        assert mission_outcome(summary, states, (x[k], y[k])) == OUTCOMES[found.result.outcome[k]], f"cell {k}"
