#!/usr/bin/env bash
# Equal time, before and after, side by side in one run: each scene under both binaries, one
# after the other, the order alternating from scene to scene so that a drifting host slows both.
# Usage: scripts/before-after-equal-time.sh BEFORE AFTER SECONDS OUTDIR, then
# scripts/equal-time-table.py OUTDIR for the speed-ups side by side.
set -euo pipefail
before=$(realpath "$1"); after=$(realpath "$2"); secs=$3; out=$(realpath -m "$4")
mkdir -p "$out"
cd "$(dirname "$0")/.."
i=0
for s in caustic-glass cornell-box env-lit glossy-interreflection indirect-room veach-mis; do
  if [ $((i % 2)) = 0 ]; then order="before after"; else order="after before"; fi
  for which in $order; do
    bin=$before; [ $which = after ] && bin=$after
    "$bin" bench equal-time "$secs" "scenes/$s/scene.xml" > "$out/$s.$which.txt" 2>&1
  done
  i=$((i + 1))
done
echo finished > "$out/done"
