#!/usr/bin/env bash
# Tests the Python client (clients/python, package tessera-client) against a real coordinator
# and worker: the debug binaries in target/debug (cargo build -p tessera-coordinator -p
# tessera-worker), one farm per test. Installs the package with its test extras into
# target/python-venv, checks its types with mypy --strict, then runs pytest.
#   scripts/test-python-client.sh [PYTEST ARGS...]
set -euo pipefail
cd "$(dirname "$0")/.."
venv="$PWD/target/python-venv"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/pip" install -q -e "clients/python[test]"
"$venv/bin/mypy" --strict clients/python/src
cd clients/python
TESSERA_BIN="${TESSERA_BIN:-$OLDPWD/target/debug}" "$venv/bin/python" -m pytest -q tests "$@"
