#!/usr/bin/env bash
# Usage: OLD=/path/to/old/pssba [NEW=target/release/pssba] [WORK=DIR] tools/compare_binaries.sh
# Pose files of the old and the new binary on the bench scenes (quick size) and the demo scene,
# every method, one window and sliding windows; cmp each pair.
set -u
OLD=${OLD:?set OLD to the pssba binary built before the change}
NEW=${NEW:-target/release/pssba}; NEW=$(realpath "$NEW")
WORK=${WORK:-/tmp/pssba-compare}; mkdir -p "$WORK"; cd "$WORK"
for scene in hangar curved truss street; do
  [ -d $scene ] || $NEW -q simulate --scene $scene --frames 30 --points-per-frame 8000 --seed 1 --out $scene
done
[ -d demo ] || $NEW -q demo --frames 20 --points 8000 --seed 2 --write-dataset demo >/dev/null
same=0; differ=0
for scene in hangar curved truss street demo; do
  for method in pss-ba pss-ba-fs point2plane balm; do
    $OLD -q adjust $scene --method $method --out $scene/old_$method.txt 2>/dev/null
    $NEW -q adjust $scene --method $method --out $scene/new_$method.txt 2>/dev/null
    if cmp -s $scene/old_$method.txt $scene/new_$method.txt; then same=$((same+1)); echo "same   $scene $method"; else differ=$((differ+1)); echo "DIFFER $scene $method"; fi
  done
  $OLD -q adjust $scene --window-frames 12 --window-stride 8 --out $scene/old_sliding.txt 2>/dev/null
  $NEW -q adjust $scene --window-frames 12 --window-stride 8 --out $scene/new_sliding.txt 2>/dev/null
  if cmp -s $scene/old_sliding.txt $scene/new_sliding.txt; then same=$((same+1)); echo "same   $scene sliding"; else differ=$((differ+1)); echo "DIFFER $scene sliding"; fi
done
echo "identical: $same, different: $differ"
