#!/usr/bin/env bash
# Renders the six original scenes with every integrator under two `tessera` binaries (say, release
# builds of two commits) and says whether their R, G, B are the same bits.
# Usage: scripts/before-after-bits.sh BEFORE AFTER OUTDIR   (needs: pip install numpy OpenEXR)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
before=$(realpath "$1"); after=$(realpath "$2"); out=$(realpath -m "$3")
mkdir -p "$out"; cd "$here/.."
for s in caustic-glass cornell-box env-lit glossy-interreflection indirect-room veach-mis; do
  for i in pt lt bdpt vcm emis-bdpt emis-vcm; do
    spp=8; case $i in emis-*) spp=24;; esac
    for which in before after; do
      bin=$before; [ $which = after ] && bin=$after
      "$bin" render "scenes/$s/scene.xml" --integrator $i --spp $spp --seed 7 -o "$out/$s.$i.$which.exr" > /dev/null 2>&1
    done
    echo "$s $i: $(python3 "$here/exr-bits.py" "$out/$s.$i.before.exr" "$out/$s.$i.after.exr")"
  done
done
