#!/usr/bin/env bash
# scripts/gpu-run.sh judged on fakes (a CLI that lists a device or none, a
# gpu-test binary with chosen outcomes, a compute-sanitizer that works or is
# refused by the runtime), so that a GPU run cannot read green having tested
# nothing: a skipped test fails the tests step, a missing device fails every
# step with the runtime's reason, a refused sanitizer is UNAVAILABLE (exit 3),
# never a memory error. The one-call default order (changed tests, their
# sanitizers, ab, profile) runs in its order within its time budget, writes
# ab.json with the card's name and clocks, and reads a missing profiler as
# UNAVAILABLE.
# Usage: tests/gpu_run_script_test.sh REPO_ROOT WORK_DIR
set -uo pipefail
[[ $# -eq 2 ]] || { echo "usage: $0 REPO_ROOT WORK_DIR" >&2; exit 2; }
root=$1
work=$2
rm -rf "$work"
mkdir -p "$work/bin" "$work/tools" "$work/profilers" "$work/repo/scripts"
# A copy of the script in a repository of its own: it finds neither the
# staged binaries nor the staged scenes of the real checkout (and so writes
# nothing into it).
cp "$root/scripts/gpu-run.sh" "$work/repo/scripts/"
fail() { echo "gpu_run_script_test: $*"; exit 1; }

# Fakes, steered by files in $work: device (present or not), tests (pass, skip, fail), sanitizer (ok, refused, errors).
cat > "$work/bin/rayforge" <<FAKE
#!/usr/bin/env bash
case "\$1" in
  bench)
    if [[ " \$* " == *" --list "* ]]; then
      printf 'GPU kernels:\n  aila-laine  (traces bvh)\n  aila-laine-fma  (traces bvh)\n  cwbvh  (traces bvh)\n'; exit 0
    fi
    previous=""
    for arg in "\$@"; do [[ "\$previous" == --json ]] && echo '{"records": [{"gpu": "Fake H200"}]}' > "\$arg"; previous=\$arg; done
    echo "fake bench \$*"; exit 0 ;;
  build) echo "fake build \$*"; exit 0 ;;
esac
if [[ "\$(cat $work/device)" == present ]]; then printf 'CUDA devices: 1\ncuda:0  Fake H200\n'
else echo 'CUDA devices: none (cudaGetDeviceCount failed: cudaErrorNoDevice: no CUDA-capable device is detected)'; fi
FAKE
cat > "$work/tools/nvidia-smi" <<'FAKE'
#!/usr/bin/env bash
case "$*" in
  *name,clocks*) printf 'name, clocks.current.sm [MHz], clocks.current.memory [MHz]\nFake H200, 1980 MHz, 3201 MHz\n' ;;
  *--query-gpu=name*) echo 'Fake H200' ;;
  *) echo 'NVIDIA-SMI fake' ;;
esac
FAKE
cat > "$work/profilers/cuobjdump" <<'FAKE'
#!/usr/bin/env bash
case "$1" in
  --dump-resource-usage) printf ' Function _Z16intersect_kernelI10Bvh2TracerEvT_:\n  REG:40 STACK:0 SHARED:0\n Function _Z11other_kernelv:\n  REG:8\n' ;;
  -sass) printf '\t\tFunction : %s\n        /*0000*/   LDG.E R0, [R2.64] ;\n        /*0010*/   BRA 0x0 ;\n' "$3" ;;
esac
FAKE
touch "$work/bin/librayforge.so"
cat > "$work/bin/rayforge_gpu_tests" <<FAKE
#!/usr/bin/env bash
case "\$(cat $work/tests)" in
  pass) echo '[  PASSED  ] 49 tests.'; exit 0 ;;
  skip) echo '[  PASSED  ] 40 tests.'; echo '[  SKIPPED ] 9 tests, listed below:'
        echo '[  SKIPPED ] GpuX.Y'; echo 'no CUDA device: fake reason'; exit 0 ;;
  fail) echo '[  PASSED  ] 47 tests.'; echo '[  FAILED  ] 2 tests, listed below:'; exit 1 ;;
esac
FAKE
cat > "$work/tools/compute-sanitizer" <<FAKE
#!/usr/bin/env bash
case "\$(cat $work/sanitizer)" in
  ok) echo '========= ERROR SUMMARY: 0 errors'; exit 0 ;;
  refused) echo '========= Error: Device not supported'; echo 'CUDA error 999: unknown error'; exit 1 ;;
  errors) if [[ "\$*" == *GpuProbe* ]]; then echo '========= ERROR SUMMARY: 0 errors'; exit 0; fi
          echo '========= Invalid __global__ read of size 4'; echo '========= ERROR SUMMARY: 3 errors'; exit 3 ;;
esac
FAKE
chmod +x "$work/bin/"* "$work/tools/"* "$work/profilers/"*

# run DEVICE TESTS SANITIZER STEPS...: the script's output in $out, its status in $rc.
# $extra_path goes in front of PATH (the fake profilers), $budget is the run's
# RAYFORGE_GPU_RUN_BUDGET; the toolkit's folders are not searched.
extra_path="" budget=480
run() {
  echo "$1" > "$work/device"; echo "$2" > "$work/tests"; echo "$3" > "$work/sanitizer"; shift 3
  rm -rf "$work/out"
  out=$(PATH="$extra_path$work/tools:$PATH" OUT="$work/out" RAYFORGE_GPU_RUN_BINARIES="$work/bin" \
    RAYFORGE_GPU_RUN_TOOL_DIRS="" RAYFORGE_GPU_RUN_BUDGET="$budget" bash "$work/repo/scripts/gpu-run.sh" "$@" 2>&1)
  rc=$?
}
expect() { grep -qF -- "$1" <<< "$out" || fail "expected '$1' in: $out"; }

run present pass ok tests sanitizers
((rc == 0)) || fail "all ok must exit 0, got $rc: $out"
expect "gpu-run: runtime: ok: cuda:0  Fake H200"
expect "gpu-run: tests: ok: 49 passed, 0 failed, 0 skipped"
expect "gpu-run: racecheck: ok: ERROR SUMMARY: 0 errors"

run present skip ok tests
((rc == 1)) || fail "a skipped test must fail the run, got $rc"
expect "gpu-run: tests: FAIL: 40 passed, 0 failed, 9 skipped: a skipped gpu test tested nothing"

run present fail ok tests
((rc == 1)) || fail "a failed test must fail the run, got $rc"
expect "gpu-run: tests: FAIL: 47 passed, 2 failed, 0 skipped, exit 1"

run present pass refused sanitizers
((rc == 3)) || fail "a refused sanitizer alone must exit 3, got $rc: $out"
expect "gpu-run: synccheck: UNAVAILABLE: compute-sanitizer unavailable on this runtime"

run present pass errors memcheck
((rc == 1)) || fail "sanitizer errors must fail the run, got $rc"
expect "gpu-run: memcheck: FAIL: 3 errors reported"

run absent skip ok tests sanitizers bench builds
((rc == 1)) || fail "no device must fail the run, got $rc"
expect "gpu-run: runtime: FAIL: no CUDA device: cudaGetDeviceCount failed: cudaErrorNoDevice"
expect "gpu-run: memcheck: FAIL: not run: no CUDA device"
expect "gpu-run: bench: FAIL: not run: no CUDA device"
expect "gpu-run: builds: FAIL: not run: no CUDA device"
[[ $(grep -c '^gpu-run: ' <<< "$out") -eq 7 ]] || fail "expected one line per step (7): $out"

# The default order: every step once, in priority order; no profiler here.
run present pass ok
((rc == 3)) || fail "the default order without profilers must exit 3, got $rc: $out"
expect "Fake H200, 1980 MHz, 3201 MHz"
order=$(sed -n 's/^gpu-run: \([a-z-]*\): .*/\1/p' <<< "$out" | tr '\n' ' ')
[[ "$order" == "runtime changed memcheck-changed racecheck-changed synccheck-changed ab profile " ]] ||
  fail "default order: got '$order'"
expect "gpu-run: changed: ok: 49 passed, 0 failed, 0 skipped"
expect "gpu-run: racecheck-changed: ok: ERROR SUMMARY: 0 errors"
expect "gpu-run: ab: ok: 3 runs, kernels aila-laine,aila-laine-fma,cwbvh"
expect "gpu-run: profile: UNAVAILABLE: ran: none; not found: cuobjdump ncu nsys"
grep -qF -- '--gpu-kernel aila-laine,aila-laine-fma,cwbvh' "$work/out/ab.txt" || fail "ab.txt lacks the kernels: $(cat "$work/out/ab.txt")"
grep -qF -- '--scene generate:terrain-statues@12M' "$work/out/ab.txt" || fail "ab.txt lacks the generated scene"
grep -qF -- '--integrator path' "$work/out/ab.txt" || fail "ab.txt lacks path tracing"
grep -qF '"card": "Fake H200"' "$work/out/ab.json" || fail "ab.json lacks the card: $(cat "$work/out/ab.json")"
grep -qF '"bench": {"records"' "$work/out/ab.json" || fail "ab.json lacks the bench records"
grep -qF '"--gtest_filter=' "$work/out/gpu-tests.txt" 2> /dev/null ||
  grep -qF -- '--gtest_filter=*AilaLaine*' "$work/out/gpu-tests.txt" || fail "the changed step names its filter"
if command -v python3 > /dev/null; then
  python3 -c 'import json, sys; json.load(open(sys.argv[1]))' "$work/out/ab.json" || fail "ab.json is not JSON"
fi
files=$(find "$work/out" -type f | wc -l)
((files <= 8)) || fail "a device call returns at most 8 files; the default order wrote $files"

# The profile step with cuobjdump: resource usage, the trace kernels' SASS and their counts.
extra_path="$work/profilers:"
run present pass ok profile
((rc == 0)) || fail "profile with cuobjdump must exit 0, got $rc: $out"
expect "gpu-run: profile: ok: ran: cuobjdump; not found: ncu nsys"
grep -qF 'Function : _Z16intersect_kernelI10Bvh2TracerEvT_' "$work/out/sass.txt" || fail "sass.txt lacks the trace kernel"
grep -qF 'other_kernel' "$work/out/sass.txt" && fail "sass.txt holds a kernel that does not trace"
grep -qE '1 LDG +0 LDL +0 STL +1 BRA' "$work/out/profile.txt" || fail "profile.txt lacks the SASS counts: $(cat "$work/out/profile.txt")"
extra_path=""

# Out of time: the budgeted steps say so and run nothing.
budget=0
run present pass ok
((rc == 3)) || fail "steps out of the budget must exit 3, got $rc: $out"
expect "gpu-run: changed: UNAVAILABLE: out of the time budget"
expect "gpu-run: memcheck-changed: UNAVAILABLE: out of the time budget"
expect "gpu-run: ab: UNAVAILABLE: out of the time budget"
expect "gpu-run: profile: UNAVAILABLE: out of the time budget"
budget=480

# No device: every step of the default order fails with the runtime's reason.
run absent pass ok
((rc == 1)) || fail "no device must fail the default order, got $rc"
for step in changed memcheck-changed racecheck-changed synccheck-changed ab profile; do
  expect "gpu-run: $step: FAIL: not run: no CUDA device"
done
echo "gpu_run_script_test: ok"
