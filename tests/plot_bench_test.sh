#!/usr/bin/env bash
# Tests scripts/plot-bench.py: it draws tests/data/bench/sample.json as a PNG,
# and reports a missing file, invalid JSON, a JSON without "records" and one
# with no records as exit 1 with exactly one line on stderr (bad usage: 2).
# Usage: tests/plot_bench_test.sh REPO_ROOT OUTPUT_DIR
# Exits 77 (skipped) when no python3 with matplotlib is found; $PYTHON, if set,
# is tried first, then python3 on PATH, then /usr/bin/python3 (the Debian
# package python3-matplotlib is only visible to the system interpreter, which
# pyenv and virtual environments hide).
set -uo pipefail

if [ $# -ne 2 ]; then
  echo "usage: $0 REPO_ROOT OUTPUT_DIR" >&2
  exit 2
fi
root=$1
out=$2
mkdir -p "$out" || exit 1
script="$root/scripts/plot-bench.py"

py=""
for candidate in "${PYTHON:-}" python3 /usr/bin/python3; do
  if [ -n "$candidate" ] && "$candidate" -c "import matplotlib" 2>/dev/null; then
    py=$candidate
    break
  fi
done
if [ -z "$py" ]; then
  echo "SKIP: no python3 with matplotlib (Debian: python3-matplotlib)"
  exit 77
fi
# A private, writable matplotlib config/cache: no cache-building or
# unwritable-home warnings on stderr, no shared state between runs.
export MPLCONFIGDIR="$out/mplconfig"
mkdir -p "$MPLCONFIGDIR"

failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }

# The sample draws, and the result is a PNG.
png="$out/sample.png"
rm -f "$png"
if ! "$py" "$script" "$root/tests/data/bench/sample.json" -o "$png" --title "plot_bench_test"; then
  fail "plotting the sample exited non-zero"
elif [ ! -s "$png" ]; then
  fail "$png was not written"
elif [ "$(head -c 8 "$png" | od -An -tx1 | tr -d ' \n')" != "89504e470d0a1a0a" ]; then
  fail "$png does not start with the PNG signature"
fi

# expect_error CODE NAME ARGS...: exits CODE; for CODE 1, exactly one stderr line.
expect_error() {
  local code=$1 name=$2
  shift 2
  "$py" "$script" "$@" >"$out/$name.stdout" 2>"$out/$name.stderr"
  local rc=$? lines
  lines=$(wc -l <"$out/$name.stderr")
  if [ "$rc" -ne "$code" ]; then
    fail "$name: exit $rc, expected $code"
  elif [ "$code" -eq 1 ] && [ "$lines" -ne 1 ]; then
    fail "$name: $lines lines on stderr, expected 1"
  else
    echo "ok: $name: exit $rc: $(tail -n 1 "$out/$name.stderr")"
  fi
}

printf '{"tool": "rayforge bench", "threads": 2}\n' >"$out/no-records.json"
printf '{"tool": "rayforge bench", "records": []}\n' >"$out/empty-records.json"
printf '{"tool": "rayforge bench", "records": [\n' >"$out/truncated.json"

expect_error 1 missing-file "$out/does-not-exist.json" -o "$out/x.png"
expect_error 1 no-records "$out/no-records.json" -o "$out/x.png"
expect_error 1 empty-records "$out/empty-records.json" -o "$out/x.png"
expect_error 1 invalid-json "$out/truncated.json" -o "$out/x.png"
expect_error 2 no-output "$root/tests/data/bench/sample.json"

if [ "$failures" -ne 0 ]; then
  echo "plot_bench_test: $failures failure(s)"
  exit 1
fi
echo "plot_bench_test: passed ($py)"
