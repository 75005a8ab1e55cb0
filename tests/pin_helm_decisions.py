"""Re-pin the helm decisions of missions/NAME.toml in tests/data/helm-decisions.json (after a
deliberate change of the physics they fly in; the arbitration itself must never move them):
    python tests/pin_helm_decisions.py alpha lateral_approach ...
It stores a `helpers.mission_trace` (how the run ended, events, sampled decisions and states), which
tests/test_helm.py compares with tolerances, so pins made on one CPU hold on any other."""

import json
import sys
from pathlib import Path

from helpers import helm_trace

ROOT = Path(__file__).resolve().parents[1]
PINS = ROOT / "tests" / "data" / "helm-decisions.json"

pins = json.loads(PINS.read_text())
for name in sys.argv[1:]:
    pins[name] = helm_trace(ROOT / "missions" / f"{name}.toml")
    print(name, pins[name]["outcome"], pins[name]["reason"], pins[name]["steps"])
PINS.write_text(json.dumps(pins, indent=1) + "\n")
