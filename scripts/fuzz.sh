#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/, with clang) into build-fuzz/ and runs
# each one for a bounded time or number of runs, one after the other.
#
#   scripts/fuzz.sh                 every target, 60 s each
#   scripts/fuzz.sh 300             every target, 300 s each
#   scripts/fuzz.sh --runs 100000   every target, 100000 executions each
#   scripts/fuzz.sh 30 obj ply      only fuzz_obj and fuzz_ply, 30 s each
#
# Seeds come from tests/fuzz/<target>/ (copied, never modified); new inputs
# go to build-fuzz/corpus/<target>/, crash reproducers to
# build-fuzz/artifacts/<target>/. Prints one line per target (executions,
# result) and exits 1 when any target crashed, leaked, hung or ran out of
# memory. Non-interactive; each run is also bounded by `timeout`.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${FUZZ_BUILD_DIR:-$ROOT/build-fuzz}"
ALL_TARGETS=(obj mtl ply gltf glb json_scene texture exr aff viewer_script bookmarks pack obj_stream)

seconds=60
runs=""
targets=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --runs) runs="$2"; shift 2 ;;
    -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
    [0-9]*) seconds="$1"; shift ;;
    *) targets+=("$1"); shift ;;
  esac
done
[[ ${#targets[@]} -eq 0 ]] && targets=("${ALL_TARGETS[@]}")

dictionary_for() {
  case "$1" in
    obj|mtl|obj_stream) echo "$ROOT/fuzz/dictionaries/obj.dict" ;;
    ply) echo "$ROOT/fuzz/dictionaries/ply.dict" ;;
    gltf|glb) echo "$ROOT/fuzz/dictionaries/gltf.dict" ;;
    json_scene) echo "$ROOT/fuzz/dictionaries/json.dict" ;;
    aff) echo "$ROOT/fuzz/dictionaries/aff.dict" ;;
    viewer_script) echo "$ROOT/fuzz/dictionaries/viewer_script.dict" ;;
    bookmarks) echo "$ROOT/fuzz/dictionaries/json.dict" ;;
    pack) echo "$ROOT/fuzz/dictionaries/pack.dict" ;;
    *) echo "" ;;
  esac
}

CXX_COMPILER="${FUZZ_CXX:-$(command -v clang++ || true)}"
C_COMPILER="${FUZZ_CC:-$(command -v clang || true)}"
if [[ -z "$CXX_COMPILER" || -z "$C_COMPILER" ]]; then
  echo "fuzz.sh: clang/clang++ not found (Debian: apt-get install clang libclang-rt-14-dev)" >&2
  exit 2
fi
jobs="${FUZZ_BUILD_JOBS:-2}"
cmake -S "$ROOT/fuzz" -B "$BUILD" -DCMAKE_CXX_COMPILER="$CXX_COMPILER" -DCMAKE_C_COMPILER="$C_COMPILER" >/dev/null
cmake --build "$BUILD" -j"$jobs" --target "${targets[@]/#/fuzz_}" >/dev/null

# ASan: a leak is a bug too; a crash stops at the first report.
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:symbolize=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
export LSAN_OPTIONS="${LSAN_OPTIONS:-suppressions=$ROOT/fuzz/lsan.supp:print_suppressions=0}"

failed=0
printf '%-12s %12s %8s  %s\n' target executions seconds result
for target in "${targets[@]}"; do
  binary="$BUILD/fuzz_$target"
  corpus="$BUILD/corpus/$target"
  artifacts="$BUILD/artifacts/$target/"
  log="$BUILD/logs/fuzz_$target.log"
  mkdir -p "$corpus" "$artifacts" "$(dirname "$log")"
  args=(-rss_limit_mb=2048 -malloc_limit_mb=2048 -timeout=10 -max_len=16384 -print_final_stats=1
        -artifact_prefix="$artifacts")
  dict="$(dictionary_for "$target")"
  [[ -n "$dict" ]] && args+=(-dict="$dict")
  if [[ -n "$runs" ]]; then
    args+=(-runs="$runs")
    limit=$((3600 * 6))
  else
    args+=(-max_total_time="$seconds")
    limit=$((seconds + 120))
  fi
  start=$(date +%s)
  status=0
  timeout --kill-after=10 "$limit" "$binary" "${args[@]}" "$corpus" "$ROOT/tests/fuzz/$target" >"$log" 2>&1 || status=$?
  elapsed=$(( $(date +%s) - start ))
  execs="$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | tail -1 | grep -o '[0-9]*$' || true)"
  if [[ $status -eq 0 ]]; then
    result="ok"
  else
    failed=1
    reason="$(grep -m1 -o 'ERROR: [A-Za-z]*Sanitizer: [a-z-]*\|ERROR: libFuzzer: [a-z-]*\|runtime error: .*\|uncaught exception\|out-of-memory' "$log" || true)"
    result="FAILED (exit $status${reason:+: $reason}); log: $log; reproducers: $artifacts"
  fi
  printf '%-12s %12s %8s  %s\n' "$target" "${execs:-?}" "$elapsed" "$result"
done
exit $failed
