#!/usr/bin/env bash
# The process system against the in-process library, at real sensor sizes (a benchmark, not a
# test: it prints numbers, it asserts nothing). Run from the repository root:
#
#   bash tools/system_bench.sh [WORKDIR]
#
# 1. Each built-in scene, 100 frames x 20,000 rays (seed 3): wall time of `pssba adjust DIR`
#    and of `pssba run --dataset DIR` with one window over all frames (the same poses), and
#    each stage's peak memory (logged by the stage itself).
# 2. A 400-frame hangar flight replayed at 10 Hz through the default windows (W 100, S 80):
#    per-window time, the lag from a frame's send to its final pose, APE.
# 3. Shared memory the run reserves (/dev/shm, sampled during the flight).
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:-$(mktemp -d)}
mkdir -p "$work"
cargo build --release --bin pssba >/dev/null
pssba=./target/release/pssba
one_window="$work/one-window.toml"
printf '[windows]\nwindow_frames = 1000\nwindow_stride = 1\n' >"$one_window"

wall() { # prints the wall time (s) of the command
    local started ended
    started=$(date +%s.%N)
    "$@" >/dev/null 2>"$work/last.log"
    ended=$(date +%s.%N)
    echo "$ended - $started" | bc
}

echo "| scene | points | pssba adjust (s) | pssba run --dataset (s) | overhead | peak MiB ingest / smooth / adjust / record |"
echo "|---|---|---|---|---|---|"
for scene in hangar curved truss street; do
    dir="$work/$scene"
    [ -d "$dir" ] || $pssba -q simulate --scene "$scene" --frames 100 --seed 3 --out "$dir"
    points=$(grep -a -h '^POINTS' "$dir"/frames/*.pcd | awk '{s += $2} END {print s}')
    t_adjust=$(wall $pssba -q adjust "$dir" --config "$one_window" --out "$work/$scene-adjust.txt")
    t_run=$(wall $pssba run --dataset "$dir" --config "$one_window" --out "$work/$scene.mcap")
    peaks=$(for stage in ingest smooth adjust record; do
        grep -o "stage $stage: peak memory [0-9]* MiB" "$work/last.log" | awk '{print $5}'
    done | paste -sd/ -)
    overhead=$(echo "scale=1; 100 * ($t_run - $t_adjust) / $t_adjust" | bc)
    printf '| %s | %s | %.2f | %.2f | %s %% | %s |\n' "$scene" "$points" "$t_adjust" "$t_run" "$overhead" "$peaks"
done

flight="$work/hangar-400"
[ -d "$flight" ] || $pssba -q simulate --scene hangar --frames 400 --seed 3 --out "$flight"
echo
echo "400-frame hangar flight at 10 Hz, default windows:"
( while sleep 1; do du -sm /dev/shm 2>/dev/null | awk '{print $1}'; done ) >"$work/shm.txt" &
sampler=$!
t_flight=$(wall $pssba run --dataset "$flight" --rate 10 --out "$work/flight.mcap")
kill "$sampler" 2>/dev/null || true
grep -o "window [0-9]*: frames [0-9]*\.\.[0-9]*" "$work/last.log" | sed 's/^/  /'
grep -o "progress: .*" "$work/last.log" | sed 's/^/  /'
grep -o "frame sent -> final pose .*" "$work/last.log" | sed 's/^/  /'
grep -o "stage [a-z]*: peak memory .*" "$work/last.log" | sed 's/^/  /'
grep "APE" "$work/last.log" | sed 's/^/  /'
echo "  wall ${t_flight} s for 40 s of data; /dev/shm peak $(sort -n "$work/shm.txt" | tail -1) MiB"
