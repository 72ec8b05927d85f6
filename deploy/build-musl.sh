#!/usr/bin/env bash
# A static host-sim for any x86-64 Linux (musl, no shared libraries), copied to
# deploy/host-sim for the container image and the batch scripts.
set -euo pipefail
cd "$(dirname "$0")/.."
rustup target add x86_64-unknown-linux-musl
cargo build --release --locked -p host-sim --target x86_64-unknown-linux-musl
# Cargo says where it builds (CARGO_TARGET_DIR may move it).
target=$(cargo metadata --format-version 1 --no-deps \
  | python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
cp "$target/x86_64-unknown-linux-musl/release/host-sim" deploy/host-sim
file deploy/host-sim 2>/dev/null || true
echo "deploy/host-sim: $(stat -c %s deploy/host-sim) bytes"
