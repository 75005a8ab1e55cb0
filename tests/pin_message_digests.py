"""Re-pin the message digests of missions/NAME.toml in tests/data/message-digests.json (after a
deliberate change of the physics; a speed-up must never move them):
    python tests/pin_message_digests.py overtake_stern_nuv recovery lateral_approach"""

import json
import sys

from test_message_digests import PINS, message_digests

pins = json.loads(PINS.read_text()) if PINS.exists() else {}
for name in sys.argv[1:]:
    pins[name] = message_digests(name)
    print(name, pins[name])
PINS.write_text(json.dumps(pins, indent=1) + "\n")
