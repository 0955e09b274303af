#!/usr/bin/env bash
# The required-GPU mode's failure path, on a machine without a usable CUDA
# device (CI, the development machines): with RAYFORGE_REQUIRE_GPU=1 the gpu
# tests must fail, each saying "no CUDA device: <the runtime's reason>", and
# skip none; without it they must skip and pass, as in the ordinary suite.
# Usage: tests/gpu_required_mode_test.sh RAYFORGE_CLI GPU_TEST_BINARY
# Exits 77 (skipped) where a device is present: the mode is then exercised by
# scripts/gpu-run.sh itself.
set -uo pipefail
[[ $# -eq 2 ]] || { echo "usage: $0 RAYFORGE_CLI GPU_TEST_BINARY" >&2; exit 2; }
cli=$1
gpu_tests=$2
if "$cli" info --devices | grep -q '^cuda:[0-9]'; then
  echo "a CUDA device is present: the failure path is not reachable here"
  exit 77
fi
filter='GpuProbe.*:GpuBvhTracer.ListsDevicesWithoutThrowing:GpuErrors.*'
fail() { echo "gpu_required_mode_test: $*"; exit 1; }

required=$(RAYFORGE_REQUIRE_GPU=1 "$gpu_tests" --gtest_filter="$filter" 2>&1)
rc=$?
echo "$required" | tail -12
((rc != 0)) || fail "RAYFORGE_REQUIRE_GPU=1 without a device exited 0"
grep -q '^\[  SKIPPED \]' <<< "$required" && fail "RAYFORGE_REQUIRE_GPU=1 still skipped tests"
reason=$(grep -m1 -o 'no CUDA device: .*' <<< "$required")
[[ -n "$reason" ]] || fail "no 'no CUDA device: ...' line in the failures"
# The runtime's own words follow, not an empty or generic reason.
[[ "$reason" =~ no\ CUDA\ device:\ .*(cuda[A-Za-z]+|runtime).*RAYFORGE_REQUIRE_GPU\ is\ set ]] ||
  fail "the reason does not carry the runtime's error: $reason"
failed=$(grep -o '^\[  FAILED  \] Gpu[A-Za-z0-9_.]*' <<< "$required" | sort -u | wc -l)
((failed >= 5)) || fail "expected every gated test to fail, saw $failed failures"

ordinary=$(env -u RAYFORGE_REQUIRE_GPU "$gpu_tests" --gtest_filter="$filter" 2>&1)
rc=$?
echo "$ordinary" | tail -4
((rc == 0)) || fail "without RAYFORGE_REQUIRE_GPU the gpu tests failed (rc $rc)"
grep -q '^\[  SKIPPED \]' <<< "$ordinary" || fail "without RAYFORGE_REQUIRE_GPU nothing was skipped"
RAYFORGE_REQUIRE_GPU=0 "$gpu_tests" --gtest_filter="$filter" > /dev/null 2>&1 || fail "RAYFORGE_REQUIRE_GPU=0 must mean not required"
echo "gpu_required_mode_test: ok ($failed tests failed as required: $reason)"
