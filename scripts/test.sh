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
echo "== fuzz the reply decoder (cargo-fuzz, 30 s)"
command -v cargo-fuzz >/dev/null 2>&1 || cargo install -q --locked cargo-fuzz
(cd firmware-protocol && RUSTC_BOOTSTRAP=1 cargo fuzz run reply_decoder -- -max_total_time=30 -seed=1)
echo "== fuzz the geometry readers, the journal and the config loader (cargo-fuzz, 5 s each)"
for target in ply stl obj off pcd xyz journal config; do
  mkdir -p "fuzz/corpus/$target"
  (cd fuzz && RUSTC_BOOTSTRAP=1 cargo fuzz run -s none -a "$target" "corpus/$target" "seeds/$target" -- -max_total_time=5 -seed=1)
done
echo "== cargo test (release, CI=${CI:-})"
cargo test --workspace --release
