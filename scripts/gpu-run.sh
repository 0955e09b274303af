#!/usr/bin/env bash
# The GPU pass, on a CUDA machine without package access (the device
# machine), writing its logs to $OUT (or ./gpu-out):
#   scripts/gpu-run.sh [STEP...]      default: all
# Steps, in the order of a first GPU run (docs/gpu.md says what to read off each):
#   tests       every gpu test; fails when any test fails or is skipped
#   sanitizers  memcheck, synccheck and racecheck (each a step of its own)
#   memcheck | synccheck | racecheck   one compute-sanitizer tool
#   bench       GPU rays (every kernel, protocol ray sets), path tracing, Garanzha 2014's builders
#   builds      every device builder on the Stanford Dragon and 2 and 15 copies of it
#   world       worlds on the device: an animated world moved with World::set_time renders, with one
#               renderer made once, what fresh renderers render each frame (refit, rebuild,
#               two-level; GpuWorld.*), and render --frames through the CLI's one world path
#               (into builds.txt)
#   animate     dynamic scenes: the device refit (1M triangles) and two-level tests' timings, the
#               device dynamic accels' tests, render --frames with --update refit (explode) and
#               two-level (nbody), and a per-frame rebuild on the device (hlbvh2, lbvh30, ploc) of
#               builtin:explode (into builds.txt)
#   python      the Python module staged by gpu-prebuild.sh: CUDA scenes against the CPU, device
#               arrays through __cuda_array_interface__ and DLPack, threads, 10M rays' Mrays/s
#               (python/tests/gpu_check.py, into builds.txt; UNAVAILABLE where it cannot import)
#   all         tests sanitizers bench builds world animate python
# Every run first checks the runtime (`rayforge info --devices`). Each step
# prints one line, "gpu-run: STEP: ok|FAIL|UNAVAILABLE[: why]", also kept in
# $OUT/summary.txt. RAYFORGE_REQUIRE_GPU=1 is exported: a gpu test that finds
# no device fails instead of skipping. Exit status: 0 when every step is ok,
# 1 when one failed, 3 when none failed but a sanitizer was unavailable on
# this runtime.
# Binaries: those staged in .gpu-prebuilt/ by scripts/gpu-prebuild.sh when
# they were built from these sources (carry .gpu-prebuilt: no build here);
# otherwise it unpacks .gpu-debs/ (scripts/gpu-bundle.sh) into a private
# prefix and builds the CLI and the gpu tests in build-gpu/. A cold build
# may not fit one 10-minute call: build-gpu/ stays while the machine is
# warm, so run the same command again.
# RAYFORGE_SANITIZER_TIMEOUT: seconds per sanitizer tool (default 150).
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${OUT:-$ROOT/gpu-out}"
mkdir -p "$out"
export RAYFORGE_REQUIRE_GPU=1
# At most 8 files come back from a device call: $out holds summary.txt
# (the step lines, nvidia-smi, the device listing), build.txt, gpu-tests.txt,
# sanitizers.txt, bench-rays.txt and .json, bench-render.txt and builds.txt;
# the rest goes to a scratch folder.
scratch=$(mktemp -d)
summary="$out/summary.txt"
: > "$summary"

steps=()
for arg in "${@:-all}"; do
  case "$arg" in
    all) steps+=(tests memcheck synccheck racecheck bench builds world animate python) ;;
    sanitizers) steps+=(memcheck synccheck racecheck) ;;
    tests | memcheck | synccheck | racecheck | bench | builds | world | animate | python) steps+=("$arg") ;;
    *) echo "usage: $0 [tests|sanitizers|memcheck|synccheck|racecheck|bench|builds|world|animate|python|all]..." >&2; exit 2 ;;
  esac
done

failed=0 unavailable=0
# report STEP ok|FAIL|UNAVAILABLE [WHY]: the step's one line.
report() {
  local line="gpu-run: $1: $2${3:+: $3}"
  echo "$line"
  echo "$line" >> "$summary"
  case "$2" in
    ok) ;;
    UNAVAILABLE) unavailable=1 ;;
    *) failed=1 ;;
  esac
}

# The digest of the sources the binaries come from (no git on the device).
source_digest() {
  (cd "$ROOT" && find src include apps bench tests cmake CMakeLists.txt -type f | LC_ALL=C sort | xargs sha1sum | sha1sum | cut -d' ' -f1)
}

# The instruction sets the prebuilt host code was compiled for (x86-64-v3).
cpu_runs_prebuilt() {
  local flag
  for flag in avx2 fma bmi2 f16c movbe; do grep -qw "$flag" /proc/cpuinfo || return 1; done
}

# Sets $rf and $gpu_tests: the staged binaries, or a build here.
# RAYFORGE_GPU_RUN_BINARIES=DIR (for tests/gpu_run_script_test.sh) takes
# DIR/rayforge and DIR/rayforge_gpu_tests as they are.
find_binaries() {
  if [[ -n "${RAYFORGE_GPU_RUN_BINARIES:-}" ]]; then
    rf="$RAYFORGE_GPU_RUN_BINARIES/rayforge"
    gpu_tests="$RAYFORGE_GPU_RUN_BINARIES/rayforge_gpu_tests"
    return 0
  fi
  local prebuilt="$ROOT/.gpu-prebuilt"
  if [[ -x "$prebuilt/bin/rayforge" && -f "$prebuilt/SOURCES" && "$(cat "$prebuilt/SOURCES")" == "$(source_digest)" ]]; then
    if ! cpu_runs_prebuilt; then
      report binaries FAIL "this CPU lacks AVX2/FMA/BMI2 (x86-64-v3), which the binaries of .gpu-prebuilt need"
      return 1
    fi
    echo "gpu-run.sh: using the binaries of .gpu-prebuilt (built from these sources, commit $(cat "$prebuilt/COMMIT" 2> /dev/null))"
    export LD_LIBRARY_PATH="$prebuilt/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
    rf="$prebuilt/bin/rayforge"
    gpu_tests="$prebuilt/bin/rayforge_gpu_tests"
    return 0
  fi
  [[ -d "$prebuilt" ]] && echo "gpu-run.sh: .gpu-prebuilt was built from other sources: building here"
  build_here
}

build_here() {
  local prefix=/tmp/rayforge-debs f
  mkdir -p "$prefix"
  shopt -s nullglob
  local debs=("$ROOT"/.gpu-debs/*.deb)
  shopt -u nullglob
  if ((${#debs[@]} == 0)); then
    report binaries FAIL "no .gpu-prebuilt from these sources and no packages in .gpu-debs: run scripts/gpu-prebuild.sh (or gpu-bundle.sh) here and carry the folder"
    return 1
  fi
  for f in "${debs[@]}"; do
    dpkg-deb -x "$f" "$prefix" || { report binaries FAIL "cannot unpack $f"; return 1; }
  done
  local lib="$prefix/usr/lib/x86_64-linux-gnu"
  export CMAKE_PREFIX_PATH="$prefix/usr:$lib/cmake${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
  # Multiarch headers (libjpeg's jconfig.h) live one level down.
  export CPATH="$prefix/usr/include:$prefix/usr/include/x86_64-linux-gnu${CPATH:+:$CPATH}"
  export LIBRARY_PATH="$lib${LIBRARY_PATH:+:$LIBRARY_PATH}"
  export LD_LIBRARY_PATH="$lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  export PATH="$prefix/usr/bin:$PATH"
  # .pc files say prefix=/usr: the sysroot puts the unpacked tree in front.
  export PKG_CONFIG_PATH="$lib/pkgconfig:$prefix/usr/share/pkgconfig"
  export PKG_CONFIG_SYSROOT_DIR="$prefix"
  local build="$ROOT/build-gpu"
  if ! {
    cmake -S "$ROOT" -B "$build" -DCMAKE_BUILD_TYPE=Release -DRAYFORGE_BUILD_BENCHMARKS=OFF \
      -DCMAKE_CUDA_ARCHITECTURES=90 &&
      cmake --build "$build" -j"$(nproc)" --target rayforge_cli rayforge_gpu_tests
  } > "$out/build.txt" 2>&1; then
    tail -40 "$out/build.txt"
    report binaries FAIL "the build failed (build.txt)"
    return 1
  fi
  rf="$build/bin/rayforge"
  gpu_tests=$(find "$build" -name rayforge_gpu_tests -type f | head -1)
}

# Sets $no_device: "" when the runtime lists a device, else why not.
check_runtime() {
  { echo "== nvidia-smi"; nvidia-smi 2>&1; echo "== rayforge info --devices"; } >> "$summary"
  local listing
  listing=$("$rf" info --devices 2>&1)
  echo "$listing" | tee -a "$summary"
  if grep -q '^cuda:[0-9]' <<< "$listing"; then
    no_device=""
    report runtime ok "$(grep -m1 '^cuda:' <<< "$listing")"
  else
    no_device=$(sed -n 's/^CUDA devices: none (\(.*\))$/\1/p' <<< "$listing")
    no_device="${no_device:-$listing}"
    report runtime FAIL "no CUDA device: $no_device"
  fi
}

# A gtest summary count: gtest_count FILE PASSED|SKIPPED|FAILED.
gtest_count() {
  local label
  case "$2" in PASSED) label='PASSED  ' ;; SKIPPED) label='SKIPPED ' ;; FAILED) label='FAILED  ' ;; esac
  sed -n "s/^\[  $label\] \([0-9]*\) tests\{0,1\}[,.].*/\1/p" "$1" | tail -1
}

step_tests() {
  local log="$out/gpu-tests.txt"
  (cd "$ROOT" && "$gpu_tests") > "$log" 2>&1
  local rc=$? passed skipped failures first
  passed=$(gtest_count "$log" PASSED) skipped=$(gtest_count "$log" SKIPPED) failures=$(gtest_count "$log" FAILED)
  passed=${passed:-0} skipped=${skipped:-0} failures=${failures:-0}
  local counts="$passed passed, $failures failed, $skipped skipped"
  if ((rc == 0 && skipped == 0 && passed > 0)); then
    report tests ok "$counts"
  elif ((rc == 0 && skipped > 0)); then
    report tests FAIL "$counts: a skipped gpu test tested nothing ($(grep -m1 -o 'no CUDA device: .*' "$log" || echo see gpu-tests.txt))"
  else
    first=$(grep -m1 -o 'no CUDA device: .*' "$log" || grep -m1 -B1 '^\[  FAILED  \]' "$log" | head -1)
    report tests FAIL "$counts, exit $rc (${first:-see gpu-tests.txt})"
  fi
}

# The tests each sanitizer tool runs: the tracers and renderer (global
# memory), and the builders, whose kernels hold the shared-memory and
# partial-mask warp code (split_level_kernel, the HLBVH2 top-level task
# kernels, window_neighbours_kernel).
builder_tests='GpuHlbvh2Build.DeviceTopLevelIsTheCpuTopLevel:GpuGridBvhBuild.SameBvhAsCpuForBothVariants:GpuPlocBuild.DeviceClusteringAndNodeBoxes'
sanitizer_filter() {
  case "$1" in
    # Every kernel once (EveryKernelMatchesBruteForce: 72 s under memcheck on
    # an H200); BuildersAndLeafSizesForTheBvhKernels repeats the same kernels
    # on other builders' trees and would not fit the time limit.
    memcheck) echo "GpuDeviceTracer.*:GpuRenderer.AovsAndCallbacks:GpuRenderer.RaySortingChangesNothing:GpuPagedDevice.HitsEqualPagedEngineWithLargeDevicePools:GpuBvhRefit.SameBoxesAsCpuRefit:GpuTwoLevel.*:GpuDynamicAccel.TwoLevelRenderMatchesTheCpu:GpuDeviceBatch.*:$builder_tests:-GpuDeviceTracer.BuildersAndLeafSizesForTheBvhKernels" ;;
    *) echo "$builder_tests" ;;
  esac
}

step_sanitizer() {
  local tool=$1 log="$out/sanitizers.txt" limit="${RAYFORGE_SANITIZER_TIMEOUT:-150}"
  if [[ -n "$no_device" ]]; then
    report "$tool" FAIL "not run: no CUDA device: $no_device"
    return
  fi
  local sanitizer
  sanitizer=$(command -v compute-sanitizer || ls /usr/local/cuda/bin/compute-sanitizer \
    /usr/local/cuda/compute-sanitizer/compute-sanitizer 2> /dev/null | head -1)
  if [[ -z "$sanitizer" ]]; then
    report "$tool" UNAVAILABLE "compute-sanitizer not found (it ships with the CUDA toolkit)"
    return
  fi
  # A trivial run first: some sandboxed runtimes refuse the sanitizer ("device
  # not supported", then error 999 at the first allocation). That is the
  # runtime's limit, not a memory error of ours.
  local probe="$scratch/probe-$tool.txt"
  (cd "$ROOT" && timeout 120 "$sanitizer" --tool "$tool" --error-exitcode 3 "$gpu_tests" \
    --gtest_filter=GpuProbe.UploadLaunchDownload) > "$probe" 2>&1
  local rc=$?
  { echo "== $tool probe (exit $rc)"; cat "$probe"; } >> "$log"
  if ((rc != 0)); then
    if grep -qiE 'not supported|error 999|cudaErrorUnknown|unknown error|unable to attach|injection' "$probe"; then
      report "$tool" UNAVAILABLE "compute-sanitizer unavailable on this runtime ($(grep -m1 -iE 'not supported|999|unknown error|unable to attach|injection' "$probe" | cut -c1-160))"
    else
      report "$tool" FAIL "the sanitizer's probe run failed, exit $rc (sanitizers.txt)"
    fi
    return
  fi
  local run="$scratch/run-$tool.txt" filter
  filter=$(sanitizer_filter "$tool")
  (cd "$ROOT" && timeout "$limit" "$sanitizer" --tool "$tool" --error-exitcode 3 "$gpu_tests" \
    --gtest_filter="$filter") > "$run" 2>&1
  rc=$?
  { echo "== $tool on $filter (exit $rc)"; cat "$run"; } >> "$log"
  local errors
  errors=$(sed -n 's/.*ERROR SUMMARY: \([0-9]*\) error.*/\1/p' "$run" | tail -1)
  case $rc in
    0) report "$tool" ok "ERROR SUMMARY: ${errors:-0} errors" ;;
    124) report "$tool" FAIL "timed out after $limit s (RAYFORGE_SANITIZER_TIMEOUT)" ;;
    3) report "$tool" FAIL "${errors:-some} errors reported (sanitizers.txt)" ;;
    *) report "$tool" FAIL "a test failed under the sanitizer, exit $rc (sanitizers.txt)" ;;
  esac
}

# Scenes staged by gpu-prebuild.sh: unpacked where the bench looks for them.
unpack_scenes() {
  [[ -d "$ROOT/.gpu-scenes" && ! -f "$ROOT/shared/scenes/views.json" ]] || return 0
  mkdir -p "$ROOT/shared/scenes"
  cp "$ROOT/.gpu-scenes/views.json" "$ROOT/shared/scenes/"
  local packed
  (cd "$ROOT/.gpu-scenes" && find . -name '*.gz') | while read -r packed; do
    mkdir -p "$ROOT/shared/scenes/$(dirname "$packed")"
    gunzip -c "$ROOT/.gpu-scenes/$packed" > "$ROOT/shared/scenes/${packed%.gz}"
  done
  echo "gpu-run.sh: scenes unpacked from .gpu-scenes into shared/scenes"
}

step_bench() {
  if [[ -n "$no_device" ]]; then
    report bench FAIL "not run: no CUDA device: $no_device"
    return
  fi
  local scenes=(--scene builtin:cornell) why=()
  [[ -d "$ROOT/shared/scenes" ]] && scenes=(--scenes-dir "$ROOT/shared/scenes" --scene sponza)
  "$rf" bench "${scenes[@]}" --device cuda --gpu-kernel all --rays primary,diffuse,shadow,ao --embree none \
    --reps 5 --json "$out/bench-rays.json" > "$out/bench-rays.txt" 2>&1 || why+=("rays")
  {
    echo "== path tracing"
    "$rf" bench "${scenes[@]}" --device cuda --integrator path --max-depth 4 --res 1024x768 --reps 20 || why+=("path")
    echo "== Garanzha 2014's builders"
    "$rf" bench --preset garanzha2014 "${scenes[@]}" --device cuda --embree none || why+=("garanzha2014")
  } > "$out/bench-render.txt" 2>&1
  if ((${#why[@]} == 0)); then
    report bench ok "${scenes[*]}"
  else
    report bench FAIL "failed: ${why[*]} (bench-rays.txt, bench-render.txt)"
  fi
}

# Garanzha 2014's table 5.1 sizes: 871K (Dragon), 1.74M (2 dragons; the table's
# 1.76M) and 13.1M (15 dragons; the table's 12.7M) triangles.
step_builds() {
  if [[ -n "$no_device" ]]; then
    report builds FAIL "not run: no CUDA device: $no_device"
    return
  fi
  local dragon="$ROOT/shared/scenes/stanford-dragon/dragon_vrip.ply" log="$out/builds.txt" rc=0
  if [[ ! -f "$dragon" ]]; then
    report builds FAIL "no $dragon (carry .gpu-scenes from scripts/gpu-prebuild.sh)"
    return
  fi
  local copies i builder scene
  for copies in 1 2 15; do
    scene="$scratch/dragon-x$copies.json"
    {
      printf '{"meshes": ['
      for ((i = 0; i < copies; ++i)); do
        ((i > 0)) && printf ', '
        printf '{"file": "%s", "transform": {"translate": [%d, 0, 0]}}' "$dragon" "$i"
      done
      printf ']}\n'
    } > "$scene"
    for builder in lbvh30 lbvh63 hlbvh2 ploc gridbvh gridbvh-split; do
      "$rf" build "$scene" --device cuda --builder "$builder" --reps 5 --convert cwbvh >> "$log" 2>&1 || rc=1
    done
    "$rf" build "$scene" --device cuda --accel grid-proximity --reps 5 >> "$log" 2>&1 || rc=1
    "$rf" build "$scene" --device cpu --builder sbvh --reps 1 >> "$log" 2>&1 || rc=1
  done
  if ((rc == 0)); then report builds ok "$(grep -c median "$log") timed builds"; else report builds FAIL "$(grep -m1 error "$log")"; fi
}

# rf::World on the device: one renderer following an animated world through
# set_time against fresh renderers (the device structure a rebuild replaces
# is read at the start of each pass), and the CLI's frames through its one
# world path with each device update method. Appended to builds.txt.
step_world() {
  if [[ -n "$no_device" ]]; then
    report world FAIL "not run: no CUDA device: $no_device"
    return
  fi
  local log="$out/builds.txt" rc=0 method
  {
    echo "== world: GpuWorld.* (one renderer across set_time against fresh renderers per frame)"
    "$gpu_tests" --gtest_filter='GpuWorld.*' || rc=1
    for method in refit rebuild two-level; do
      echo "== world: render builtin:nbody --device cuda --update $method --frames 0:99:33"
      "$rf" render builtin:nbody --device cuda --update "$method" --frames 0:99:33 --res 128x96 -q \
        -o "$scratch/world_${method}_%03d.png" || rc=1
    done
  } >> "$log" 2>&1
  if ((rc == 0)); then report world ok "GpuWorld.* passed; frames in builds.txt"; else report world FAIL "$(grep -m1 -E 'error|FAILED' "$log")"; fi
}

# The dynamic scenes' device figures: refit and two-level kernels (their tests print
# kernel ms), the device dynamic accels' tests, the explosion refitted on the
# device and the n bodies traced two-level there, and the structure rebuilt
# on the device every frame of an explosion (render --frames prints each
# frame's update). Appended to
# builds.txt: a device call brings back at most 8 files.
step_animate() {
  if [[ -n "$no_device" ]]; then
    report animate FAIL "not run: no CUDA device: $no_device"
    return
  fi
  local log="$out/builds.txt" rc=0 builder
  {
    echo "== animate: device refit, two-level tracer and the device dynamic accels"
    "$gpu_tests" --gtest_filter='GpuBvhRefit.*:GpuTwoLevel.*:GpuDynamicAccel.*' || rc=1
    echo "== animate: builtin:explode refitted on the device every 11th frame (cwbvh converted again; bvh2 in place)"
    "$rf" render builtin:explode --device cuda --update refit --frames 0:99:11 --res 256x192 -q \
      -o "$scratch/explode_refit_%03d.png" || rc=1
    "$rf" render builtin:explode --device cuda --update refit --gpu-kernel bvh2 --frames 0:99:11 --res 256x192 -q \
      -o "$scratch/explode_refit2_%03d.png" || rc=1
    echo "== animate: builtin:nbody two-level on the device every 11th frame"
    "$rf" render builtin:nbody --device cuda --update two-level --frames 0:99:11 --res 256x192 -q \
      -o "$scratch/nbody_%03d.png" || rc=1
    for builder in hlbvh2 lbvh30 ploc; do
      echo "== animate: builtin:explode rebuilt on the device every 11th frame, $builder"
      "$rf" render builtin:explode --device cuda --update rebuild --builder "$builder" --frames 0:99:11 \
        --res 256x192 -q -o "$scratch/explode_%03d.png" || rc=1
    done
  } >> "$log" 2>&1
  if ((rc == 0)); then report animate ok "figures in builds.txt"; else report animate FAIL "$(grep -m1 -E 'error|FAILED' "$log")"; fi
}

# The Python module on the device (staged by gpu-prebuild.sh when its build
# had one): python/tests/gpu_check.py traces with a CUDA RaycastingScene and
# World from several threads, through both device-array interfaces, against
# the CPU, and times cast_rays_on_device on 10M rays (Mrays/s end to end).
# UNAVAILABLE where the module cannot load (another Python than it was built
# for). Appended to builds.txt.
step_python() {
  if [[ -n "$no_device" ]]; then
    report python FAIL "not run: no CUDA device: $no_device"
    return
  fi
  local log="$out/builds.txt" package="$ROOT/.gpu-prebuilt/python"
  if [[ ! -d "$package/rayforge" ]]; then
    report python UNAVAILABLE "no module staged in .gpu-prebuilt/python (its build had no Python)"
    return
  fi
  local python
  python=$(command -v python3 || true)
  if [[ -z "$python" ]] || ! PYTHONPATH="$package" "$python" -c "import rayforge" >> "$log" 2>&1; then
    report python UNAVAILABLE "the module does not import with ${python:-no python3} here ($(tail -1 "$log" | cut -c1-120))"
    return
  fi
  echo "== python: python/tests/gpu_check.py" >> "$log"
  if PYTHONPATH="$package" timeout 300 "$python" "$ROOT/python/tests/gpu_check.py" >> "$log" 2>&1; then
    report python ok "$(grep -m1 'Mrays/s' "$log")"
  else
    report python FAIL "$(tail -1 "$log" | cut -c1-160)"
  fi
}

if find_binaries; then
  check_runtime
  unpack_scenes
  for step in "${steps[@]}"; do
    case "$step" in
      tests) step_tests ;;
      memcheck | synccheck | racecheck) step_sanitizer "$step" ;;
      bench) step_bench ;;
      builds) step_builds ;;
      world) step_world ;;
      animate) step_animate ;;
      python) step_python ;;
    esac
  done
else
  for step in "${steps[@]}"; do report "$step" FAIL "not run: no binaries"; done
fi
rm -rf "$scratch"
echo "gpu-run.sh: summary in $summary"
if ((failed)); then exit 1; fi
if ((unavailable)); then exit 3; fi
exit 0
