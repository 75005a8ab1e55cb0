"""Re-pin the message traces of missions/NAME.toml in tests/data/message-traces.json (after a
deliberate change of the physics; a speed-up must never move them beyond a CPU's last bits):
    python tests/pin_message_digests.py overtake_stern_nuv recovery lateral_approach
It stores a `helpers.mission_trace` of every topic, which tests/test_message_digests.py compares
with tolerances, so pins made on one CPU hold on any other."""

import json
import sys

from test_message_digests import PINS, message_trace

pins = json.loads(PINS.read_text()) if PINS.exists() else {}
for name in sys.argv[1:]:
    pins[name] = message_trace(name)
    print(name, pins[name]["outcome"], pins[name]["reason"], pins[name]["steps"])
PINS.write_text(json.dumps(pins, indent=1) + "\n")
