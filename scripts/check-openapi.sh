#!/usr/bin/env bash
# Checks the REST API against its OpenAPI document (issue 70): starts a coordinator with tokens
# and a worker, submits a job, validates /api/v1/openapi.json with openapi-spec-validator, then
# runs schemathesis (seeded) against the live API: every operation with schema-valid and
# invalid data, responses checked against the document, stateful sequences, the real job's and
# worker's routes included (scripts/openapi/schemathesis.toml).
#   scripts/check-openapi.sh [MAX_EXAMPLES]        (default 25 per operation)
# Needs the debug binaries (cargo build -p tessera-coordinator -p tessera-worker) and Python 3
# with pip; the two Python tools are installed into target/openapi-venv.
set -euo pipefail
cd "$(dirname "$0")/.."
examples="${1:-25}"
bin="$PWD/target/debug"
venv="$PWD/target/openapi-venv"
if [ ! -x "$venv/bin/schemathesis" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install -q "openapi-spec-validator==0.7.*" "schemathesis==4.*"
fi
work="$(mktemp -d)"
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$work"' EXIT
"$bin/tessera" serve --data-dir "$work/data" --listen 127.0.0.1:0 --client-token api-check \
    --worker-token api-worker >"$work/serve.out" 2>"$work/serve.log" &
for _ in $(seq 100); do
    url="$(sed -n 's/^tessera serve: listening on //p' "$work/serve.out")"
    [ -n "$url" ] && break
    sleep 0.1
done
[ -n "$url" ] || { echo "check-openapi: the coordinator did not start" >&2; cat "$work/serve.log" >&2; exit 1; }
"$bin/tessera-worker" --coordinator "$url" --threads 1 --token api-worker --cache-dir "$work/cache" >"$work/worker.log" 2>&1 &
auth="Authorization: Bearer api-check"
curl -sf "$url/api/v1/openapi.json" -o "$work/openapi.json"
"$venv/bin/python" -c "
import json, sys
from openapi_spec_validator import validate
doc = json.load(open(sys.argv[1]))
validate(doc)
print('check-openapi: the document is valid OpenAPI', doc['openapi'], 'with', len(doc['paths']), 'paths')
" "$work/openapi.json"
export TESSERA_JOB TESSERA_WORKER
TESSERA_JOB="$(curl -sf -H "$auth" -F "scene=@scenes/cornell-box/scene.xml;filename=scene.xml" \
    -F 'settings={"integrator":"pt","spp":4096,"seed":1,"name":"api check"}' "$url/api/v1/jobs" \
    | "$venv/bin/python" -c 'import json, sys; print(json.load(sys.stdin)["id"])')"
for _ in $(seq 100); do
    TESSERA_WORKER="$(curl -sf -H "$auth" "$url/api/v1/workers" | "$venv/bin/python" -c 'import json, sys; w = json.load(sys.stdin); print(w[0]["id"] if w else "")')"
    [ -n "$TESSERA_WORKER" ] && break
    sleep 0.1
done
"$venv/bin/schemathesis" --no-color --config-file scripts/openapi/schemathesis.toml run "$url/api/v1/openapi.json" \
    -H "$auth" --max-examples "$examples" --seed 1
# the coordinator took all of it and still answers
curl -sf "$url/healthz" >/dev/null || { echo "check-openapi: the coordinator stopped" >&2; tail -20 "$work/serve.log" >&2; exit 1; }
echo "check-openapi: passed"
