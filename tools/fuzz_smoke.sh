#!/usr/bin/env bash
# A short run of every cargo-fuzz target (CI's smoke test; the long runs are in the notes of
# fuzz/README.md of crates/pssba-bag and crates/pssba-system). Needs the nightly toolchain and cargo-fuzz: both are
# installed here if missing. If the nightly toolchain cannot be installed, says so and skips
# (exit 0) rather than failing the build for a missing toolchain; a crash found fails (exit 1).
# Usage: tools/fuzz_smoke.sh [SECONDS_PER_TARGET]
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-30}"
if ! cargo +nightly --version >/dev/null 2>&1; then
  rustup toolchain install nightly --profile minimal || true
fi
if ! cargo +nightly --version >/dev/null 2>&1; then
  echo "== fuzz smoke: SKIPPED: no nightly toolchain on this machine and none could be installed"
  exit 0
fi
if ! command -v cargo-fuzz >/dev/null 2>&1; then
  cargo install cargo-fuzz --locked --version 0.13.2
fi
for crate in crates/pssba-bag crates/pssba-system; do
(
cd "$crate"
cargo +nightly fuzz build -O
for target in $(cargo +nightly fuzz list); do
  scratch="$(mktemp -d)"
  echo "== fuzz smoke: $target for ${seconds}s"
  # New inputs go to the scratch corpus; the committed seeds are read only. One malloc may be
  # up to 4.1 GiB: mcap 0.26 (through binrw) reserves a string's claimed u32 length before
  # reading it; that memory is never touched (the read then fails), and RSS stays capped at
  # 2 GiB. tests/fixtures/fuzz_findings/mcap_string_length_4gib.mcap is that input.
  set +e
  cargo +nightly fuzz run -O "$target" "$scratch" "fuzz/corpus/$target" -- \
    -max_total_time="$seconds" -max_len=65536 -rss_limit_mb=2048 -malloc_limit_mb=4200 -timeout=10 -print_final_stats=1 \
    >"$scratch.log" 2>&1
  status=$?
  set -e
  grep -E "stat::number_of_executed_units|ERROR|panicked|SUMMARY|Done" "$scratch.log" || tail -20 "$scratch.log"
  rm -rf "$scratch" "$scratch.log"
  if [ "$status" -ne 0 ]; then
    echo "== fuzz smoke: $target FAILED (exit $status); the input is in $crate/fuzz/artifacts/$target"
    exit 1
  fi
done
)
done
echo "== fuzz smoke: every target ran without a finding"
