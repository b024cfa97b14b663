#!/usr/bin/env bash
# /healthz latency seen from a separate process while `tessera bench farm --ingest` loads the
# coordinator it starts (1080p vcm and emis-vcm with EMIS updates): a curl every 10 ms on a
# new connection; prints p50, p99 and the worst, in ms.
#   cargo build --release -p tessera-coordinator && scripts/healthz-under-load.sh
set -euo pipefail
cd "$(dirname "$0")/.."
log=$(mktemp)
target/release/tessera bench farm --ingest --pt-frame 256x256 --vcm-frame 1920x1080 --vcm-iterations 6 > "$log" 2>&1 &
bench=$!
times=$(mktemp)
while kill -0 "$bench" 2>/dev/null; do
    # the bench's coordinator is its child `tessera serve` (one at a time)
    port=$(ss -ltnpH 2>/dev/null | grep '"tessera"' | grep -o '127.0.0.1:[0-9]*' | head -1 || true)
    if [ -n "$port" ]; then
        # a refused connection is a coordinator between two cases (counted apart); a timeout is not
        curl -s -o /dev/null -m 5 -w "%{time_total}\n" "http://$port/healthz" >> "$times" || echo "failed $?" >> "$times"
    fi
    sleep 0.01
done
grep -E "tiles/s|healthz" "$log" | cut -c1-120
grep -c failed "$times" | xargs -I{} echo "failed probes: {} (curl exit codes: $(grep failed "$times" | sort | uniq -c | tr -s ' \n' ' '))"
grep -v failed "$times" | sort -g | awk '{a[NR]=$1} END {printf "external /healthz: %d probes, p50 %.1f ms, p99 %.1f ms, worst %.1f ms\n", NR, a[int(NR*0.5)]*1000, a[int(NR*0.99)]*1000, a[NR]*1000}'
rm -f "$log" "$times"
