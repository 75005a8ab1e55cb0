#!/usr/bin/env bash
# Set everything up in .venv and run the default mission (the README's first command).
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e .
# numba compiles the LF's and the helm's kernels once into its cache here, not in a mission's first processes.
.venv/bin/python -m nearsub.tools.support.kernels
exec .venv/bin/nearsub launch "${1:-missions/alpha.toml}" "${@:2}"
