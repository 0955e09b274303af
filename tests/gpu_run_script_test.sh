#!/usr/bin/env bash
# scripts/gpu-run.sh judged on fakes (a CLI that lists a device or none, a
# gpu-test binary with chosen outcomes, a compute-sanitizer that works or is
# refused by the runtime), so that a GPU run cannot read green having tested
# nothing: a skipped test fails the tests step, a missing device fails every
# step with the runtime's reason, a refused sanitizer is UNAVAILABLE (exit 3),
# never a memory error.
# Usage: tests/gpu_run_script_test.sh REPO_ROOT WORK_DIR
set -uo pipefail
[[ $# -eq 2 ]] || { echo "usage: $0 REPO_ROOT WORK_DIR" >&2; exit 2; }
root=$1
work=$2
rm -rf "$work"
mkdir -p "$work/bin" "$work/tools" "$work/repo/scripts"
# A copy of the script in a repository of its own: it finds neither the
# staged binaries nor the staged scenes of the real checkout (and so writes
# nothing into it).
cp "$root/scripts/gpu-run.sh" "$work/repo/scripts/"
fail() { echo "gpu_run_script_test: $*"; exit 1; }

# Fakes, steered by files in $work: device (present or not), tests (pass, skip, fail), sanitizer (ok, refused, errors).
cat > "$work/bin/rayforge" <<FAKE
#!/usr/bin/env bash
if [[ "\$(cat $work/device)" == present ]]; then printf 'CUDA devices: 1\ncuda:0  Fake H200\n'
else echo 'CUDA devices: none (cudaGetDeviceCount failed: cudaErrorNoDevice: no CUDA-capable device is detected)'; fi
FAKE
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
chmod +x "$work/bin/"* "$work/tools/"*

# run DEVICE TESTS SANITIZER STEPS...: the script's output in $out, its status in $rc.
run() {
  echo "$1" > "$work/device"; echo "$2" > "$work/tests"; echo "$3" > "$work/sanitizer"; shift 3
  out=$(PATH="$work/tools:$PATH" OUT="$work/out" RAYFORGE_GPU_RUN_BINARIES="$work/bin" bash "$work/repo/scripts/gpu-run.sh" "$@" 2>&1)
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
echo "gpu_run_script_test: ok"
