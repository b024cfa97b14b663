#!/usr/bin/env bash
# The adversarial suite of issue 67 (decision 0015) on release builds: per case the answer,
# the time to answer and the peak RSS of the coordinator and the worker, as a Markdown table.
# With a folder of an older build's binaries, each case runs against it too, right before
# this build's run of it.
#   scripts/hostile-requests.sh [OLD/target/release] [--case NAME ...]
# The suite itself is tests/src/hostile/; connection floods in detail: scripts/hostile/connections.py.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -p tessera-coordinator -p tessera-worker -p tessera-tests
before=()
if [ $# -gt 0 ] && [ "${1#--}" = "$1" ]; then
    before=(--before "$1")
    shift
fi
target/release/hostile-suite --bin-dir target/release "${before[@]}" "$@"
