#!/usr/bin/env bash
# Sourced by scripts/test.sh and the peer benchmark: prepares what the tests need, outside the
# clone so that repeated runs from fresh clones reuse it.
#   POLISHBOT_CACHE   cache root (default ~/.cache/polishbot)
#   CARGO_TARGET_DIR  cargo's target dir (default $POLISHBOT_CACHE/target)
#   POLISHBOT_PYTHON  the test venv's python (exported for the Rust tests)
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cache="${POLISHBOT_CACHE:-$HOME/.cache/polishbot}"
mkdir -p "$cache"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$cache/target}"

# Debian packages: libusb for Open3D's wheel, chromium for the report test.
need_apt=()
[ -e /usr/lib/x86_64-linux-gnu/libusb-1.0.so.0 ] || ldconfig -p 2>/dev/null | grep -q libusb-1.0.so.0 || need_apt+=(libusb-1.0-0)
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium)
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "test-env: installing Debian packages: ${need_apt[*]}" >&2
  sudo_cmd=""; [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
  $sudo_cmd apt-get update -qq >/dev/null
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

# Python venv keyed by the requirements' hash.
req="$repo/tests/requirements.txt"
key="$(sha256sum "$req" | cut -c1-12)"
venv="$cache/venv-$key"
if [ ! -x "$venv/bin/python" ] || [ ! -f "$venv/.complete" ]; then
  echo "test-env: creating $venv" >&2
  rm -rf "$venv"
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q --disable-pip-version-check -r "$req"
  touch "$venv/.complete"
fi
export POLISHBOT_PYTHON="$venv/bin/python"
