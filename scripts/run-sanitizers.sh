#!/usr/bin/env bash
# Builds rayforge with sanitizers (CUDA left out) and runs the test suite under
# them; any sanitizer report fails the run.
#   scripts/run-sanitizers.sh            AddressSanitizer + UndefinedBehaviorSanitizer, whole suite
#   scripts/run-sanitizers.sh thread     ThreadSanitizer on the multi-threaded builder and renderer tests
# Build folders: build-asan/ and build-tsan/. Prints the wall time of each step.
set -euo pipefail
cd "$(dirname "$0")/.."
mode="${1:-address}"
jobs="${RAYFORGE_JOBS:-$(nproc)}"

case "$mode" in
  address)
    build_dir=build-asan
    sanitize="address,undefined"
    # The install test links an uninstrumented consumer against the instrumented library; the
    # ASan runtime cannot be preloaded there, so it runs in the normal build only.
    ctest_args=(-LE "install|gpu" -E "CyclesReference")  # the Cycles comparisons are statistics over long renders; Release runs them
    export ASAN_OPTIONS="detect_leaks=1:abort_on_error=1:strict_string_checks=1:detect_stack_use_after_return=1"
    export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1"
    export LSAN_OPTIONS="suppressions=$PWD/tests/sanitizers/lsan.supp:print_suppressions=0"
    ;;
  thread)
    build_dir=build-tsan
    sanitize="thread"
    # Every test that runs TBB-parallel code (builders of every structure, flattening, rendering, batched
    # traversal, bench) and the viewer session's own threads; not the viewer's window tests, whose
    # OpenGL (Mesa) and X libraries are not instrumented.
    ctest_args=(-R "Bvh|BinnedSah|Render|PathTracer|WavefrontPath|ShadingTriangles|EndToEnd|SceneGeometry|Builtin|Bench|KdTree|UniformGrid|ProximityGrid|Lbvh|Hlbvh2|Ploc|Hploc|Treelet|Sbvh|SweepSah|Reinsertion|AccelMatrix|Session|Paged|PageCache|ReaderPool|UringReader|PageCodec|SharedAttributes|Generate|World|MeshQueries" -E "ViewerGui" -LE "install|gpu")
    export TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1"
    ;;
  *) echo "usage: $0 [address|thread]" >&2; exit 2 ;;
esac

start=$(date +%s)
# The Python module is left out: an instrumented extension needs the sanitizer runtime preloaded into
# the interpreter, and its C++ underneath (World, MeshQueries) is tested here by the C++ suite.
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DRAYFORGE_ENABLE_CUDA=OFF \
      -DRAYFORGE_ENABLE_PYTHON=OFF -DRAYFORGE_BUILD_BENCHMARKS=OFF -DRAYFORGE_SANITIZE="$sanitize" | grep -E "^-- rayforge" || true
cmake --build "$build_dir" -j "$jobs"
built=$(date +%s)
ctest --test-dir "$build_dir" --output-on-failure -j "$jobs" "${ctest_args[@]}"
done_at=$(date +%s)
echo "sanitizers ($sanitize): build $((built - start)) s, tests $((done_at - built)) s"
