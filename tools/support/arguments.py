"""argparse types for the command line's numbers: a value out of range (NaN and infinities
included) stops argparse before the tool runs, naming the option and the value, exit code 2.

    parser.add_argument("--repeats", type=integer(minimum=1), default=3)
    parser.add_argument("--timeout", type=number(above=0.0), default=30.0)
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def _bounds_text(minimum, maximum, above) -> str:
    parts = []
    if above is not None:
        parts.append(f"> {above:g}")
    if minimum is not None:
        parts.append(f">= {minimum:g}")
    if maximum is not None:
        parts.append(f"<= {maximum:g}")
    return " and ".join(parts)


def integer(minimum: int | None = None, maximum: int | None = None) -> Callable[[str], int]:
    """A whole number within [minimum, maximum] (either may be open)."""
    wanted = " ".join(filter(None, ("a whole number", _bounds_text(minimum, maximum, None))))

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"wants {wanted}, got {text!r}") from None
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"wants {wanted}, got {text!r}")
        return value

    parse.__name__ = "integer"  # argparse names the type in its messages
    return parse


def number(
    minimum: float | None = None, maximum: float | None = None, above: float | None = None
) -> Callable[[str], float]:
    """A finite number within [minimum, maximum], and greater than `above` when given."""
    wanted = " ".join(filter(None, ("a finite number", _bounds_text(minimum, maximum, above))))

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"wants {wanted}, got {text!r}") from None
        if (
            not math.isfinite(value)
            or (minimum is not None and value < minimum)
            or (maximum is not None and value > maximum)
            or (above is not None and value <= above)
        ):
            raise argparse.ArgumentTypeError(f"wants {wanted}, got {text!r}")
        return value

    parse.__name__ = "number"
    return parse


# A step number: a mission has at most 10**12 steps (common/mission/schema.py, MAX_STEPS, which
# this light module does not import), far inside the 64-bit integers msgpack carries.
STEP = integer(minimum=1, maximum=10**12)
