#!/usr/bin/env bash
# Fuzzes Tessera's parsers of hostile input (issue 67) with the cargo-fuzz targets in fuzz/:
# builds them on the stable toolchain (no sanitizer: fuzz/README.md says why), replays the
# reproducers under fuzz/regressions/, then runs each target for SECONDS under `nice -n 19`
# with libFuzzer's 1 GiB RSS limit and 10 s timeout, going on after a finding, and prints per
# target the executions, the time and what it found.
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]      (default: 60 s, every target)
# Environment:
#   FUZZ_WORK         folder for new corpus entries, findings and logs, one folder per target
#                     (default: a new temporary folder; kept, the checked-in corpus is only read)
#   CARGO_TARGET_DIR  the build's target folder (default: fuzz/target)
#   FUZZ_NO_BUILD=1   use the binaries already built
#   FUZZ_BUILD_FLAGS  more flags for `cargo fuzz build` (e.g. "--codegen-units 16")
#   FUZZ_VMEM_MB      address-space limit of each fuzzing process (default 4096), so that one
#                     huge allocation fails at once instead of slipping past the RSS check
# Exits 1 when a target that fuzz/known-findings does not name finds a crash, OOM or timeout,
# or fails one of its reproducers (replayed with TESSERA_FUZZ_STRICT=1, so a caught panic
# fails); findings of the targets it names are printed only. Caught panics found while fuzzing
# (caught-panic-* files) are counted but do not fail the run: commit one as a reproducer to
# hold the decoder to it.
set -euo pipefail
cd "$(dirname "$0")/.."

seconds="${1:-60}"
shift || true
command -v cargo-fuzz >/dev/null || { echo "fuzz.sh: cargo-fuzz is missing: cargo install cargo-fuzz --locked" >&2; exit 2; }
targets=("$@")
[ ${#targets[@]} -gt 0 ] || mapfile -t targets < <(cargo fuzz list)
target_dir="${CARGO_TARGET_DIR:-$PWD/fuzz/target}"
bin_dir="$target_dir/$(rustc -vV | sed -n 's/^host: //p')/release"
work="${FUZZ_WORK:-$(mktemp -d "${TMPDIR:-/tmp}/tessera-fuzz.XXXXXX")}"
scratch_base=/dev/shm
[ -d "$scratch_base" ] && [ -w "$scratch_base" ] || scratch_base="$work"
scratch=$(mktemp -d "$scratch_base/tessera-fuzz-scratch.XXXXXX")
trap 'rm -rf "$scratch"' EXIT

# the longest input each target is given (bytes)
max_len() {
    case "$1" in
        scene_xml | scene_build | emis_wire) echo 16384 ;;
        *) echo 8192 ;;
    esac
}

dict_flag() {
    case "$1" in
        scene_xml | scene_build) echo "-dict=fuzz/dict/scene.dict" ;;
        mesh_ply) echo "-dict=fuzz/dict/ply.dict" ;;
        mesh_obj) echo "-dict=fuzz/dict/obj.dict" ;;
    esac
}

known() {
    grep -qE "^$1([[:space:]]|$)" fuzz/known-findings 2>/dev/null
}

build() {
    [ "${FUZZ_NO_BUILD:-0}" = 1 ] && return
    local start=$SECONDS
    # shellcheck disable=SC2086 # FUZZ_BUILD_FLAGS is a list of flags
    CARGO_TARGET_DIR="$target_dir" nice -n 19 cargo fuzz build -O -s none ${FUZZ_BUILD_FLAGS:-}
    echo "fuzz.sh: built in $((SECONDS - start)) s"
}

# Replays fuzz/regressions/TARGET/*; prints "passed failed".
replay() {
    local t=$1 passed=0 failed=0 f
    for f in fuzz/regressions/"$t"/*; do
        [ -f "$f" ] || continue
        # strict: a reproducer of a panic that the code catches fails too; at normal priority,
        # so that other work on the machine cannot push a slow-input reproducer (a few seconds
        # of CPU) past the timeout that fuzzing uses
        if TESSERA_FUZZ_STRICT=1 TESSERA_FUZZ_SCRATCH="$scratch" "$bin_dir/$t" -rss_limit_mb=1024 -timeout=10 "$f" \
            >"$work/$t/replay.log" 2>&1; then
            passed=$((passed + 1))
        else
            failed=$((failed + 1))
            echo "fuzz.sh: $t: reproducer $f still fails (log: $work/$t/replay.log)" >&2
        fi
    done
    echo "$passed $failed"
}

# Fuzzes TARGET for $seconds; libFuzzer's fork mode goes on after crashes, OOMs and timeouts.
run() {
    local t=$1 dir="$work/$1"
    # shellcheck disable=SC2046 # dict_flag is one flag or none
    (
        ulimit -v $((${FUZZ_VMEM_MB:-4096} * 1024))
        TESSERA_FUZZ_SCRATCH="$scratch" TESSERA_FUZZ_ARTIFACTS="$dir/artifacts" exec nice -n 19 "$bin_dir/$t" \
            -fork=1 -ignore_crashes=1 -ignore_ooms=1 -ignore_timeouts=1 \
            -max_total_time="$seconds" -rss_limit_mb=1024 -timeout=10 -report_slow_units=2 \
            -max_len="$(max_len "$t")" $(dict_flag "$t") -artifact_prefix="$dir/artifacts/" \
            "$dir/corpus" "fuzz/corpus/$t"
    ) >"$dir/fuzz.log" 2>&1
}

count() {
    find "$1" -maxdepth 1 -name "$2-*" | wc -l
}

build
mkdir -p "$work"
printf '%-16s %10s %6s %5s %4s %7s %4s %12s %9s %s\n' target executions time crash oom timeout slow caught-panic replayed ok >"$work/summary"
status=0
for t in "${targets[@]}"; do
    [ -x "$bin_dir/$t" ] || { echo "fuzz.sh: no binary for target $t in $bin_dir" >&2; exit 2; }
    mkdir -p "$work/$t/corpus" "$work/$t/artifacts"
    read -r passed failed < <(replay "$t")
    start=$SECONDS
    run "$t" || { echo "fuzz.sh: $t: libFuzzer failed (log: $work/$t/fuzz.log)" >&2; status=1; }
    elapsed=$((SECONDS - start))
    execs=$(grep -oE '^#[0-9]+: cov' "$work/$t/fuzz.log" | tail -1 | tr -dc '0-9')
    a="$work/$t/artifacts"
    crash=$(count "$a" crash) oom=$(count "$a" oom) timeout=$(count "$a" timeout)
    found=$((crash + oom + timeout + failed))
    ok=yes
    if [ "$found" -gt 0 ]; then
        if known "$t"; then ok="known"; else ok=NO; status=1; fi
    fi
    printf '%-16s %10s %5ss %5s %4s %7s %4s %12s %9s %s\n' "$t" "${execs:-0}" "$elapsed" "$crash" "$oom" \
        "$timeout" "$(count "$a" slow-unit)" "$(count "$a" caught-panic)" "$passed/$((passed + failed))" "$ok" \
        | tee -a "$work/summary"
done
echo
cat "$work/summary"
echo "fuzz.sh: logs, new corpus entries and findings in $work"
exit $status
