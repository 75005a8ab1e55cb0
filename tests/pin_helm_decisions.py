"""Re-pin the helm decisions of missions/NAME.toml in tests/data/helm-decisions.json (after a
deliberate change of the physics they fly in; the arbitration itself must never move them):
    python tests/pin_helm_decisions.py alpha lateral_approach ..."""

import json
import sys
from pathlib import Path

from helpers import helm_decisions

ROOT = Path(__file__).resolve().parents[1]
PINS = ROOT / "tests" / "data" / "helm-decisions.json"

pins = json.loads(PINS.read_text())
for name in sys.argv[1:]:
    pins[name] = helm_decisions(ROOT / "missions" / f"{name}.toml")
    print(name, pins[name])
PINS.write_text(json.dumps(pins, indent=1) + "\n")
