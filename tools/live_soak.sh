#!/usr/bin/env bash
# Soak of the live interface (issue 13): the example producer (crates/pssba-client/examples/
# replay_folder.rs) streams a dataset folder forwards and backwards into
# `pssba run --input live` for DURATION seconds at RATE Hz; the example consumer writes the
# final poses. Prints each stage's RSS near the start and at the end, frames sent, recorded
# and final, and the stage logs' latency lines.
#
#   bash tools/live_soak.sh DIR [DURATION_S=600] [RATE_HZ=10] [OVERFLOW=block] [OUT=/tmp/pssba-soak]
set -euo pipefail
dir=${1:?dataset folder}
duration=${2:-600}
rate=${3:-10}
overflow=${4:-block}
out=${5:-/tmp/pssba-soak}
root=$(cd "$(dirname "$0")/.." && pwd)
cargo build --release --quiet --bin pssba -p pssba-cli
cargo build --release --quiet -p pssba-client --examples
bin=$root/target/release
mkdir -p "$out"
instance="soak-$$"
printf '[system]\nlive_overflow = "%s"\n' "$overflow" >"$out/soak.toml"

"$bin/pssba" run --input live --instance "$instance" --config "$out/soak.toml" \
  --out "$out/soak.mcap" --json >"$out/summary.json" 2>"$out/run.log" &
run_pid=$!
"$bin/examples/write_tum" --instance "$instance" --out "$out/final.tum" 2>"$out/write_tum.log" &
tum_pid=$!
"$bin/examples/replay_folder" "$dir" --instance "$instance" --rate "$rate" \
  --duration "$duration" 2>"$out/producer.log" &
producer_pid=$!

rss() { # "stage=RSS_MB ..." of the stage processes
  for pid in $(pgrep -f "pssba.*stage (smooth|adjust|record)" || true); do
    stage=$(tr '\0' ' ' </proc/"$pid"/cmdline | grep -oE 'stage [a-z]+' | cut -d' ' -f2)
    kb=$(awk '/VmRSS/ {print $2}' /proc/"$pid"/status 2>/dev/null || echo 0)
    printf '%s=%dMB ' "$stage" $((kb / 1024))
  done
}
sleep 30
echo "RSS at 30 s: $(rss)" | tee "$out/rss.log"
elapsed=30
while kill -0 "$producer_pid" 2>/dev/null; do
  sleep 30
  elapsed=$((elapsed + 30))
  echo "RSS at $elapsed s: $(rss)" | tee -a "$out/rss.log"
done
wait "$producer_pid"
wait "$run_pid" && run_status=0 || run_status=$?
wait "$tum_pid" || true
echo "exit status of pssba run: $run_status"
grep -h "sent \|final poses in" "$out/producer.log" "$out/write_tum.log" || true
grep -hE "frame sent -> final|frame transport|frames final in|dropped|wrote" "$out/run.log" || true
cat "$out/summary.json"
