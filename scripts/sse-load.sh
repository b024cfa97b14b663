#!/usr/bin/env bash
# Measures what server-sent events cost the coordinator (issue 70): one worker renders a 1080p
# job (cornell-box at 1920x1080, pt) while the coordinator's CPU time is read from /proc over
# SECONDS, first with no event stream open, then with CLIENTS streams (half on /api/v1/events,
# half on the job's own stream). Prints the coordinator's CPU use in both phases and the events
# one client of each kind received.
#   scripts/sse-load.sh [BIN_DIR] [CLIENTS] [SECONDS]     (default: target/release, 50, 60)
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${1:-target/release}"
clients="${2:-50}"
seconds="${3:-60}"
work="$(mktemp -d)"
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$work"' EXIT
sed -e 's/name="width" value="256"/name="width" value="1920"/' \
    -e 's/name="height" value="256"/name="height" value="1080"/' scenes/cornell-box/scene.xml >"$work/scene.xml"
"$bin/tessera" serve --data-dir "$work/data" --listen 127.0.0.1:0 >"$work/serve.out" 2>"$work/serve.log" &
serve_pid=$!
for _ in $(seq 100); do
    url="$(sed -n 's/^tessera serve: listening on //p' "$work/serve.out")"
    [ -n "$url" ] && break
    sleep 0.1
done
"$bin/tessera-worker" --coordinator "$url" --threads 1 --cache-dir "$work/cache" >"$work/worker.log" 2>&1 &
job="$(curl -sf -F "scene=@$work/scene.xml;filename=scene.xml" \
    -F 'settings={"integrator":"pt","time_s":3600,"seed":1,"name":"sse load"}' "$url/api/v1/jobs" \
    | python3 -c 'import json, sys; print(json.load(sys.stdin)["id"])')"
until curl -sf "$url/api/v1/jobs/$job" | python3 -c 'import json, sys; sys.exit(json.load(sys.stdin)["tiles_done"] < 2)'; do
    sleep 1
done
ticks="$(getconf CLK_TCK)"
cpu() { awk '{ print $14 + $15 }' "/proc/$serve_pid/stat"; }
measure() {
    local before after
    before="$(cpu)"
    sleep "$seconds"
    after="$(cpu)"
    python3 -c "print(f'{($after - $before) / $ticks / $seconds * 100:.2f}')"
}
idle="$(measure)"
for i in $(seq "$clients"); do
    if [ $((i % 2)) -eq 0 ]; then path="/api/v1/events"; else path="/api/v1/jobs/$job/events"; fi
    curl -sN "$url$path" >"$work/client-$i.txt" &
done
sleep 1
busy="$(measure)"
tiles="$(curl -sf "$url/api/v1/jobs/$job" | python3 -c 'import json, sys; print(json.load(sys.stdin)["tiles_done"])')"
echo "coordinator CPU, 1080p pt job rendering on one worker thread, ${seconds} s each:"
echo "  no event streams:      ${idle} % of one core"
echo "  ${clients} event streams:     ${busy} % of one core"
echo "  events one client got: all $(grep -c '^event:' "$work/client-2.txt"), job $(grep -c '^event:' "$work/client-1.txt") (tiles done by the end: $tiles)"
