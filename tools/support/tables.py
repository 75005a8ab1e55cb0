"""The console the tools print their rich tables on."""

from __future__ import annotations

import sys

PIPED_WIDTH = 160  # piped output is read whole (grep, less): wide enough that no cell is cut


def console():
    from rich.console import Console

    return Console(width=None if sys.stdout.isatty() else PIPED_WIDTH)
