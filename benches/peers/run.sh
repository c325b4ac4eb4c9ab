#!/usr/bin/env bash
# The peer table in one command: bash benches/peers/run.sh [--dir DIR]
# Sets up the test environment (scripts/test-env.sh: Debian packages, the Python venv with
# Open3D, small_gicp and py4dgeo) unless POLISHBOT_PYTHON already names a python, then runs
# benches/peers/run.py with it.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
if [ -z "${POLISHBOT_PYTHON:-}" ]; then
  # shellcheck source=../../scripts/test-env.sh
  source "$repo/scripts/test-env.sh"
fi
exec "$POLISHBOT_PYTHON" "$repo/benches/peers/run.py" "$@"
