#!/usr/bin/env bash
# The whole test suite: installs what the tests need (Debian packages, a Python venv with the
# oracles and pyserial, kept outside the clone), then checks format, lints and runs every test.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/test-env.sh
echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy -D warnings"
cargo clippy --workspace --all-targets --release -- -D warnings
echo "== dofbot-protocol builds no_std"
cargo build -q -p dofbot-protocol --no-default-features --release
echo "== cargo test (release, CI=${CI:-})"
cargo test --workspace --release
