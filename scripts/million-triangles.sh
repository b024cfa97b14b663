#!/usr/bin/env bash
# Memory check: generates a 1,002,528-triangle OBJ (a wavy 708 x 708 grid with no normals, so
# smooth normals are computed too), loads it, builds the BVH and renders it, and prints the
# `tessera render` summary, which includes the peak resident memory of the whole process.
#   scripts/million-triangles.sh [OUT_DIR]      (default: a temporary folder)
set -euo pipefail
cd "$(dirname "$0")/.."
dir="${1:-$(mktemp -d)}"
mkdir -p "$dir"
python3 - "$dir/grid.obj" <<'PY'
import math, sys
n = 708
with open(sys.argv[1], "w") as f:
    for j in range(n + 1):
        for i in range(n + 1):
            x, z = i / n * 2 - 1, j / n * 2 - 1
            f.write(f"v {x:.6f} {0.05 * math.sin(12 * x) * math.cos(9 * z):.6f} {z:.6f}\n")
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i + 1
            f.write(f"f {a} {a + n + 1} {a + 1}\nf {a + 1} {a + n + 1} {a + n + 2}\n")
PY
cat > "$dir/scene.xml" <<'XML'
<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="6"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="0, 1.6, 2.2" target="0, 0, 0" up="0, 1, 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="16"/></sampler>
    <film type="hdrfilm"><integer name="width" value="256"/><integer name="height" value="256"/><rfilter type="box"/></film>
  </sensor>
  <shape type="obj"><string name="filename" value="grid.obj"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.6"/></bsdf></shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
  <emitter type="point"><point name="position" value="0.5, 2, 0.5"/><rgb name="intensity" value="4"/></emitter>
</scene>
XML
echo "mesh: $(du -h "$dir/grid.obj" | cut -f1), $(grep -c '^f ' "$dir/grid.obj") triangles"
cargo build --release -q
/usr/bin/env time -v ./target/release/tessera render "$dir/scene.xml" -o "$dir/grid.exr" 2>"$dir/time.txt" || { cat "$dir/time.txt"; exit 1; }
grep -E "Maximum resident|Elapsed" "$dir/time.txt" || true
