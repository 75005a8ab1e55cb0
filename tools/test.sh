#!/usr/bin/env bash
# Set everything up in .venv and run the default test suite (the README's second command).
set -euo pipefail
cd "$(dirname "$0")/.."
# The viewer's browser test (tests/test_viewer.py) drives Debian's headless Chromium: install it
# where it is missing and apt-get exists (CI and the developers' machines run as root).
if [ ! -x /usr/bin/chromium ] && command -v apt-get >/dev/null 2>&1; then
    if [ "$(id -u)" -eq 0 ]; then
        echo "tools/test.sh: installing Debian's chromium for the viewer's browser test" >&2
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null
    else
        echo "tools/test.sh: chromium is missing; install it as root: apt-get install chromium chromium-driver" >&2
    fi
fi
# The RANS smoke case (tests/test_rans.py) meshes and solves with Debian's OpenFOAM (v1912):
# install it the same way where it is missing.
if ! command -v simpleFoam >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then
    if [ "$(id -u)" -eq 0 ]; then
        echo "tools/test.sh: installing Debian's openfoam for the RANS smoke case" >&2
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq openfoam >/dev/null
    else
        echo "tools/test.sh: OpenFOAM is missing; install it as root: apt-get install openfoam" >&2
    fi
fi
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e '.[dev]'
# numba compiles the LF's and the helm's kernels once into its cache here, not in a mission's first processes.
.venv/bin/python -m nearsub.tools.support.kernels
# The default run on two workers: most tests wait on processes and clocks, so two at once halve its
# wall time on 2 cores. A marked suite (-m reliability, slow, soak, cfd) loads the machine on purpose
# or runs long alone: one process. An -n given here wins either way.
workers=(-n 2)
for arg in "$@"; do
    if [ "$arg" = "-m" ]; then workers=(-n 0); fi
done
exec .venv/bin/python -m pytest "${workers[@]}" "$@"
