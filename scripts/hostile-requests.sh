#!/usr/bin/env bash
# Submits each hostile scene of issue 19 to a fresh release coordinator on loopback and prints
# the answer, the time to refuse (curl's time_total) and the coordinator's peak RSS after it.
#   cargo build --release -p tessera-coordinator && scripts/hostile-requests.sh
set -euo pipefail
cd "$(dirname "$0")/.."
work=$(mktemp -d)
trap 'kill "$pid" 2>/dev/null; rm -rf "$work"' EXIT
python3 - "$work" <<'PY'
import sys
out = sys.argv[1]
xml = open("scenes/cornell-box/scene.xml").read()
add = lambda extra: xml.replace("</scene>", extra + "\n</scene>", 1)
chain = '<default name="p0" value="xxxxxxxxxx"/>' + "".join(
    f'<default name="p{i}" value="{("$p%d" % (i - 1)) * 10}"/>' for i in range(1, 10))
cases = {
    "devzero": add('<shape type="obj"><string name="filename" value="/dev/zero"/></shape>'),
    "outside": add('<shape type="ply"><string name="filename" value="../../../etc/passwd"/></shape>'),
    "include": add('<include filename="/etc/passwd"/>'),
    "film65535": xml.replace('value="256"', 'value="65535"', 2),
    "defaults": xml.replace("<sensor", chain + "<sensor", 1).replace(
        '<sensor type="perspective">', '<sensor type="perspective"><string name="label" value="$p9"/>', 1),
    "nodes": xml.replace("</scene>", "<a/>" * 1_000_001 + "</scene>", 1),
}
for name, text in cases.items():
    open(f"{out}/{name}.xml", "w").write(text)
PY
target/release/tessera serve --listen 127.0.0.1:0 --data-dir "$work/data" > "$work/out" 2> "$work/log" &
pid=$!
until grep -q http "$work/out" 2>/dev/null; do sleep 0.1; done
url=$(grep -o 'http://[0-9.:]*' "$work/out" | head -1)
echo "baseline $(grep VmHWM /proc/$pid/status)"
# large bundles (sparse files, so nothing is read from disk to make them): one within the
# default 1024 MiB --max-upload-mb is accepted, written to disk as it arrives; one over it,
# sent chunked without a length, is cut off as it arrives (first, so that the peak RSS is theirs)
truncate -s 1000M "$work/big-within.bin"
truncate -s 1100M "$work/big-over.bin"
for size in within over; do
    answer=$(curl -s -o "$work/resp" -w "%{http_code} %{time_total}s" -H "Transfer-Encoding: chunked" \
        -F "scene=@scenes/cornell-box/scene.xml;filename=scene.xml" -F 'settings={"spp":1}' \
        -F "big=@$work/big-$size.bin;filename=big.bin" "$url/api/v1/jobs")
    echo "bundle $size the limit: $answer $(grep VmHWM /proc/$pid/status | tr -s ' \t' ' ') $(head -c 120 "$work/resp")"
done
submit() { # NAME SCENE SETTINGS
    answer=$(curl -s -o "$work/resp" -w "%{http_code} %{time_total}s" -F "scene=@$2;filename=scene.xml" \
        -F "settings=$3" "$url/api/v1/jobs")
    echo "$1: $answer $(grep VmHWM /proc/$pid/status | tr -s ' \t' ' ') $(head -c 120 "$work/resp")"
}
for name in devzero outside include film65535 defaults nodes; do
    submit "$name" "$work/$name.xml" '{"integrator":"pt","spp":1}'
done
submit vcm4e9 scenes/cornell-box/scene.xml '{"integrator":"vcm","spp":4000000000}'
# a page on another origin posting a form
answer=$(curl -s -o "$work/resp" -w "%{http_code} %{time_total}s" -H "Origin: http://evil.example" \
    -F "scene=@scenes/cornell-box/scene.xml;filename=scene.xml" -F 'settings={"spp":1}' "$url/api/v1/jobs")
echo "cross-origin: $answer $(grep VmHWM /proc/$pid/status | tr -s ' \t' ' ') $(head -c 120 "$work/resp")"
