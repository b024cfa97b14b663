#!/usr/bin/env bash
# The deployment test: the farm as users run it, on a Docker engine.
#
#   1. static checks: `systemd-analyze verify` of deploy/systemd (when systemd-analyze exists),
#      `kubectl kustomize deploy/k8s` renders a ScaledObject, and the output validates against
#      Kubernetes' schemas (kubernetes-validate, from PyPI into a cached venv, when it installs);
#   2. deploy/docker/build-images.sh: the release build and the images;
#   3. deploy/compose.yaml brought up as its own project with a coordinator and three workers;
#      a job is submitted from the host with the CLI; mid-job one worker is killed (docker kill),
#      another is cut off the network (docker network disconnect) for longer than its lease and
#      reconnected, and the coordinator container is restarted;
#   4. the farm's EXR equals `tessera render` of the same scene, settings and seed bit for bit;
#   5. everything is torn down, volumes included (also on failure).
#
# Knobs: TESSERA_TEST_SPP (samples per pixel of the job, default 1024), TESSERA_TEST_TIMEOUT
# (seconds the job may take, default 600), CARGO_TARGET_DIR.
set -euo pipefail

repo=$(cd "$(dirname "$0")/.." && pwd)
cd "$repo"
target_dir=${CARGO_TARGET_DIR:-$repo/target}
bin=$target_dir/release
scene=scenes/cornell-box/scene.xml
spp=${TESSERA_TEST_SPP:-1024}
seed=20
job_timeout=${TESSERA_TEST_TIMEOUT:-600}
# short leases so that the network cut outlives one in seconds, not minutes
lease_timeout=6
cut_seconds=15
cache=${XDG_CACHE_HOME:-$HOME/.cache}/tessera-deploy

step() { printf '\n== deploy/test.sh [%3ds] %s\n' "$SECONDS" "$*"; }
note() { echo "   $*"; }
fail() { echo "deploy/test.sh: FAIL: $*" >&2; exit 1; }

# ---------------------------------------------------------------------------------------------
step "systemd units"
if command -v systemd-analyze >/dev/null; then
    units=$(mktemp -d)
    # verify wants the executables to exist: point the units at the ones the build makes
    # (checked below, after the build); the template is checked as an instance
    for f in deploy/systemd/*.service; do
        name=$(basename "$f")
        [ "$name" = "tessera-worker@.service" ] && name="tessera-worker@1.service"
        sed "s#/usr/local/bin/#$bin/#g" "$f" >"$units/$name"
    done
else
    units=""
    note "skipped: systemd-analyze is not installed"
fi

step "kubernetes manifests"
if command -v kubectl >/dev/null; then
    rendered=$(mktemp)
    kubectl kustomize deploy/k8s >"$rendered" || fail "kubectl kustomize deploy/k8s failed"
    for kind in Namespace Service StatefulSet Deployment ScaledObject TriggerAuthentication PodDisruptionBudget NetworkPolicy; do
        grep -q "^kind: $kind\$" "$rendered" || fail "kubectl kustomize deploy/k8s renders no $kind"
    done
    note "kubectl kustomize deploy/k8s: $(grep -c '^kind:' "$rendered") objects, a ScaledObject among them"
    validator=""
    if command -v kubernetes-validate >/dev/null; then
        validator=kubernetes-validate
    elif [ -x "$cache/venv/bin/kubernetes-validate" ]; then
        validator=$cache/venv/bin/kubernetes-validate
    elif mkdir -p "$cache" && python3 -m venv "$cache/venv" >/dev/null 2>&1 \
        && timeout 180 "$cache/venv/bin/pip" install -q kubernetes-validate >/dev/null 2>&1; then
        validator=$cache/venv/bin/kubernetes-validate
    fi
    if [ -n "$validator" ]; then
        # KEDA's kinds have no schema there (CRDs): they are reported as warnings and checked
        # against the live /metrics below
        "$validator" --strict --quiet "$rendered" || fail "the rendered manifests do not validate"
        note "validated against Kubernetes $("$validator" --version 2>/dev/null | awk '{print $NF}') schemas (strict)"
    else
        note "schema validation skipped: kubernetes-validate did not install from PyPI"
    fi
else
    rendered=""
    note "skipped: kubectl is not installed (Debian: apt-get install kubernetes-client)"
fi

# ---------------------------------------------------------------------------------------------
step "images (release build)"
deploy/docker/build-images.sh
for image in tessera:local tessera-worker:local; do
    user=$(docker image inspect --format '{{.Config.User}}' "$image")
    health=$(docker image inspect --format '{{json .Config.Healthcheck.Test}}' "$image")
    version=$(docker image inspect --format '{{ index .Config.Labels "org.opencontainers.image.version" }}' "$image")
    [ -n "$user" ] && [ "${user%%:*}" != 0 ] && [ "${user%%:*}" != root ] || fail "$image runs as root"
    case "$health" in *'"CMD","tessera","healthcheck"'*) ;; *) fail "$image has no exec-form health check: $health" ;; esac
    [ -n "$version" ] || fail "$image has no version label"
    note "$image: user $user, version $version, health check $health"
done

if [ -n "$units" ]; then
    out=$(cd "$units" && systemd-analyze verify tessera-coordinator.service tessera-worker@1.service 2>&1) \
        || fail "systemd-analyze verify: $out"
    # verify only warns (exit 0) about unknown keys and bad values: any output is a failure
    [ -z "$out" ] || fail "systemd-analyze verify: $out"
    for u in tessera-coordinator.service tessera-worker@1.service; do
        note "$u: verified, $(cd "$units" && systemd-analyze security --offline=yes "$u" 2>/dev/null | tail -n 1 | sed 's/^→ //')"
    done
    rm -rf "$units"
fi

# ---------------------------------------------------------------------------------------------
step "compose: a coordinator and three workers"
project=tessera-test-$$-$RANDOM
work=$(mktemp -d)
compose() { docker-compose -p "$project" -f deploy/compose.yaml -f "$work/compose.test.yaml" "$@"; }
if ! command -v docker-compose >/dev/null; then
    compose() { docker compose -p "$project" -f deploy/compose.yaml -f "$work/compose.test.yaml" "$@"; }
fi
cleanup() {
    rc=$?
    if [ "$rc" != 0 ] && [ -f "$work/compose.test.yaml" ]; then
        echo "--- last log lines of the farm" >&2
        compose logs --no-color --tail=25 2>&1 | tail -n 120 >&2 || true
    fi
    [ -n "${submit_pid:-}" ] && kill "$submit_pid" 2>/dev/null || true
    if [ -f "$work/compose.test.yaml" ]; then
        compose down -v --remove-orphans --timeout 10 >/dev/null 2>&1 || true
        left=$(docker volume ls -q --filter "label=com.docker.compose.project=$project" | wc -l)
        containers=$(docker ps -aq --filter "label=com.docker.compose.project=$project" | wc -l)
        echo "deploy/test.sh: torn down $project: $containers containers and $left volumes left" >&2
    fi
    rm -rf "$work" "${rendered:-}"
    exit "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

export TESSERA_CLIENT_TOKEN TESSERA_WORKER_TOKEN TESSERA_PORT TESSERA_WORKER_CPUS TESSERA_WORKER_DRAIN
TESSERA_CLIENT_TOKEN=$(head -c 24 /dev/urandom | od -An -tx1 | tr -d ' \n')
TESSERA_WORKER_TOKEN=$(head -c 24 /dev/urandom | od -An -tx1 | tr -d ' \n')
TESSERA_PORT=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
# one CPU (so one thread and one tile) per worker: three workers on a small machine, and every
# worker holds a tile most of the time
TESSERA_WORKER_CPUS=1
TESSERA_WORKER_DRAIN=60s
# the test's only change to compose.yaml: short leases
cat >"$work/compose.test.yaml" <<EOF
services:
  coordinator:
    command: ["serve", "--listen", "0.0.0.0:7878", "--data-dir", "/var/lib/tessera", "--insecure",
              "--lease-timeout", "$lease_timeout"]
EOF
server=http://127.0.0.1:$TESSERA_PORT
tessera() { "$bin/tessera" "$@"; }
# GET a coordinator path with the client token (Python: the test needs no curl)
api() {
    python3 - "$server$1" "$TESSERA_CLIENT_TOKEN" <<'EOF'
import sys, urllib.request
req = urllib.request.Request(sys.argv[1], headers={"Authorization": "Bearer " + sys.argv[2]})
sys.stdout.write(urllib.request.urlopen(req, timeout=10).read().decode())
EOF
}
metric() { api /metrics | awk -v m="$1" '$1 == m { print $2; found = 1 } END { if (!found) print "" }'; }
job_field() { tessera status "$job" --server "$server" --token "$TESSERA_CLIENT_TOKEN" --json | python3 -c "import json, sys; print(json.load(sys.stdin)['$1'])"; }
wait_until() { # SECONDS WHAT COMMAND...
    local limit=$((SECONDS + $1)) what=$2
    shift 2
    until "$@" >/dev/null 2>&1; do
        [ "$SECONDS" -lt "$limit" ] || fail "timed out waiting for $what"
        sleep 1
    done
}
workers_seen() { [ "$(metric tessera_workers)" -ge "$1" ]; }
leased_at_least() { [ "$(metric tessera_tiles_leased)" -ge "$1" ]; }

compose up -d --scale worker=3 2>&1 | sed 's/^/   /'
wait_until 60 "the coordinator's /healthz" tessera healthcheck --quiet "$server"
wait_until 90 "three workers" workers_seen 3
mapfile -t workers < <(compose ps -q worker)
[ "${#workers[@]}" = 3 ] || fail "expected 3 worker containers, found ${#workers[@]}"
network=$(docker inspect --format '{{range $k, $v := .NetworkSettings.Networks}}{{$k}} {{end}}' "${workers[1]}" | awk '{print $1}')
note "project $project on $server; network $network; 3 workers registered"

# the metrics KEDA scales on (deploy/k8s/keda.yaml) are served, unlabelled, as it parses them
if [ -n "$rendered" ]; then
    for m in $(awk '/valueLocation:/ { print $2 }' "$rendered" | sort -u); do
        api /metrics | grep -Eq "^$m [0-9]+\$" || fail "/metrics has no plain sample of $m, which deploy/k8s/keda.yaml scales on"
        api /metrics | grep -q "^# TYPE $m gauge\$" || fail "$m is not a gauge"
    done
    note "/metrics serves what the ScaledObject reads: $(awk '/valueLocation:/ { print $2 }' "$rendered" | sort -u | tr '\n' ' ')"
fi

# ---------------------------------------------------------------------------------------------
step "a job from the host; faults mid-job"
tessera submit "$scene" --server "$server" --token "$TESSERA_CLIENT_TOKEN" --integrator pt --spp "$spp" --seed "$seed" \
    --wait -o "$work/farm.exr" >"$work/submit.out" 2>"$work/submit.err" &
submit_pid=$!
job_started=$SECONDS
wait_until 30 "the job id" test -s "$work/submit.out"
job=$(head -n 1 "$work/submit.out")
note "job $job: $scene, pt, $spp spp, seed $seed, $(job_field tiles_total) tiles"
still_running() { # WHAT
    local state
    state=$(job_field state)
    case "$state" in
        done) fail "the job finished before $1: raise TESSERA_TEST_SPP (now $spp) so that the faults land mid-job" ;;
        failed|cancelled) fail "the job is $state: $(job_field error)" ;;
    esac
}

wait_until 60 "every worker holding a tile" leased_at_least 3
still_running "the worker kill"
expired_before=$(metric tessera_leases_expired_total)
docker kill "${workers[0]}" >/dev/null
note "killed worker ${workers[0]:0:12} (SIGKILL) holding a tile; tiles done $(job_field tiles_done)"
# its tile goes back to the queue when its lease lapses, or at once when the restart policy
# brings the worker back and it registers again
killed_tile_requeued() {
    [ "$(metric tessera_leases_expired_total)" -gt "$expired_before" ] \
        || [ "$(docker inspect --format '{{.State.Running}}' "${workers[0]}")" = true ]
}
wait_until $((lease_timeout * 3)) "the killed worker's tile to be re-queued" killed_tile_requeued
note "its tile was re-queued ($(metric tessera_leases_expired_total) leases expired so far)"

expired_before=$(metric tessera_leases_expired_total)
still_running "the network cut"
docker network disconnect "$network" "${workers[1]}"
note "cut worker ${workers[1]:0:12} off $network for ${cut_seconds}s (lease timeout ${lease_timeout}s)"
sleep "$cut_seconds"
expired_after=$(metric tessera_leases_expired_total)
docker network connect "$network" "${workers[1]}"
[ "$expired_after" -gt "$expired_before" ] || fail "no lease expired while a worker was cut off ($expired_before -> $expired_after)"
note "reconnected it; leases expired meanwhile: $((expired_after - expired_before)); tiles done $(job_field tiles_done)"

still_running "the coordinator restart"
done_before_restart=$(job_field tiles_done)
compose restart -t 10 coordinator 2>&1 | sed 's/^/   /'
wait_until 60 "the restarted coordinator's /healthz" tessera healthcheck --quiet "$server"
note "restarted the coordinator with $done_before_restart tiles done; it answers again"

step "waiting for the job"
limit=$((job_started + job_timeout))
while kill -0 "$submit_pid" 2>/dev/null; do
    [ "$SECONDS" -lt "$limit" ] || fail "the job did not finish in ${job_timeout}s ($(job_field tiles_done) of $(job_field tiles_total) tiles)"
    sleep 2
done
wait "$submit_pid" || { cat "$work/submit.err" >&2; fail "tessera submit --wait failed"; }
submit_pid=""
farm_seconds=$((SECONDS - job_started))
restarts=$(docker inspect --format '{{.RestartCount}} {{.State.Status}}' "${workers[0]}")
note "done in ${farm_seconds}s; accepted results $(metric tessera_results_accepted_total), ignored (stale) $(metric tessera_results_ignored_total) since the restart"
note "the killed worker: restart count ${restarts% *}, now ${restarts#* }"

# a crash (unlike docker kill, a manual stop to Docker) is restarted by the restart policy;
# signalling a process of another user from the host takes root
if [ "$(id -u)" = 0 ]; then
    crashed=${workers[2]}
    kill -KILL "$(docker inspect --format '{{.State.Pid}}' "$crashed")"
    restarted() { [ "$(docker inspect --format '{{.RestartCount}} {{.State.Running}}' "$crashed")" = "1 true" ]; }
    wait_until 30 "the restart policy to restart a crashed worker" restarted
    note "crashed worker ${crashed:0:12} (its process killed from the host) was restarted"
else
    note "restart of a crashed worker not checked: killing a container's process takes root"
fi

# ---------------------------------------------------------------------------------------------
step "the farm's image against tessera render"
local_started=$SECONDS
tessera render "$scene" --integrator pt --spp "$spp" --seed "$seed" -o "$work/local.exr" 2>&1 | tail -n 1 | sed 's/^/   /'
note "local render took $((SECONDS - local_started))s"
if ! python3 deploy/tools/exr-equal.py "$work/farm.exr" "$work/local.exr" >"$work/compare.out" 2>&1; then
    sed 's/^/   /' "$work/compare.out"
    fail "the farm's image differs from tessera render's"
fi
sed 's/^/   /' "$work/compare.out"

step "teardown"
trap - EXIT
cleanup_rc=0
compose down -v --remove-orphans --timeout 10 2>&1 | sed 's/^/   /' || cleanup_rc=$?
left=$(docker volume ls -q --filter "label=com.docker.compose.project=$project" | wc -l)
containers=$(docker ps -aq --filter "label=com.docker.compose.project=$project" | wc -l)
rm -rf "$work" "${rendered:-}"
[ "$cleanup_rc" = 0 ] && [ "$left" = 0 ] && [ "$containers" = 0 ] \
    || fail "teardown left $containers containers and $left volumes of $project"
echo
echo "deploy/test.sh: PASS in ${SECONDS}s (job ${farm_seconds}s on the farm, bit-identical to tessera render)"
