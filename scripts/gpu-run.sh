#!/usr/bin/env bash
# The GPU pass, on a CUDA machine without package access (the device
# machine), writing its logs to $OUT (or ./gpu-out):
#   scripts/gpu-run.sh [STEP...]      default: the one-call order below
# Steps (docs/gpu.md, "The device script", says what to read off each):
#   changed     the changed kernels' and builders' gpu tests (RAYFORGE_CHANGED_TESTS,
#               a gtest filter of broad patterns); fails when any fails or is skipped
#   memcheck-changed    memcheck on the changed kernels' tests (RAYFORGE_CHANGED_MEMCHECK)
#   racecheck-changed, synccheck-changed   on the changed builders (RAYFORGE_CHANGED_BUILDERS)
#   ab          A/B timings in one call, old and new variants side by side: Sponza
#               1024x768 primary (scanline and Morton) and diffuse with aila-laine,
#               aila-laine-fma, cwbvh and cwbvh-fma (those the binary knows) on binned
#               and SBVH trees; the same on 15 Dragons and a 12M-triangle generated
#               scene (larger than L2); lbvh30, hlbvh2, ploc and hploc on the Dragon
#               (with and without --treelets where the CLI has it); path tracing
#               passes/s and trace share per kernel (ab.txt, ab.json)
#   profile     cuobjdump resource usage and the trace kernels' SASS, Nsight Compute on
#               single launches (primary and diffuse per kernel), Nsight Systems on the
#               device builds; each tool where `command -v` finds it (profile.txt, sass.txt)
#   default     changed memcheck-changed racecheck-changed synccheck-changed ab profile:
#               the one-call order, in priority order, within RAYFORGE_GPU_RUN_BUDGET
#               seconds (480): each of these steps gets its own timeout, cut to what is
#               left; a step with no time left reads UNAVAILABLE (out of the time budget)
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
#   all         tests sanitizers bench builds world animate python (several calls: no budget)
# Every run first checks the runtime (`rayforge info --devices`) and prints
# the card's clocks once (nvidia-smi --query-gpu=name,clocks.sm,clocks.mem).
# Each step prints one line, "gpu-run: STEP: ok|FAIL|UNAVAILABLE[: why]", also
# kept in $OUT/summary.txt, as soon as it ends; each step writes its files
# under $OUT as it goes, so a run cut off by the call's limit still returns
# what finished. RAYFORGE_REQUIRE_GPU=1 is exported: a gpu test that finds
# no device fails instead of skipping. Exit status: 0 when every step is ok,
# 1 when one failed, 3 when none failed but a sanitizer or tool was
# unavailable on this runtime or a step ran out of the time budget.
# Binaries: those staged in .gpu-prebuilt/ by scripts/gpu-prebuild.sh when
# they were built from these sources (carry .gpu-prebuilt: no build here);
# otherwise it unpacks .gpu-debs/ (scripts/gpu-bundle.sh) into a private
# prefix and builds the CLI and the gpu tests in build-gpu/. A cold build
# may not fit one 10-minute call: build-gpu/ stays while the machine is
# warm, so run the same command again.
# RAYFORGE_SANITIZER_TIMEOUT: seconds per sanitizer tool of the sanitizers
# steps (default 150).
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${OUT:-$ROOT/gpu-out}"
mkdir -p "$out"
export RAYFORGE_REQUIRE_GPU=1
# At most 8 files come back from a device call. The default order writes
# summary.txt (the step lines, nvidia-smi, the device listing), build.txt
# (only when it builds), gpu-tests.txt, sanitizers.txt, ab.txt, ab.json,
# profile.txt and sass.txt; `all` writes summary.txt, build.txt,
# gpu-tests.txt, sanitizers.txt, bench-rays.txt and .json, bench-render.txt
# and builds.txt (so do not mix the two in one call); the rest goes to a
# scratch folder.
scratch=$(mktemp -d)
summary="$out/summary.txt"
: > "$summary"

steps=()
for arg in "${@:-default}"; do
  case "$arg" in
    default) steps+=(changed memcheck-changed racecheck-changed synccheck-changed ab profile) ;;
    all) steps+=(tests memcheck synccheck racecheck bench builds world animate python) ;;
    sanitizers) steps+=(memcheck synccheck racecheck) ;;
    changed | memcheck-changed | racecheck-changed | synccheck-changed | ab | profile | tests | memcheck | \
      synccheck | racecheck | bench | builds | world | animate | python) steps+=("$arg") ;;
    *)
      echo "usage: $0 [default|changed|memcheck-changed|racecheck-changed|synccheck-changed|ab|profile|tests|sanitizers|memcheck|synccheck|racecheck|bench|builds|world|animate|python|all]..." >&2
      exit 2
      ;;
  esac
done

# The one-call budget of the default order's steps (SECONDS counts from the start).
budget="${RAYFORGE_GPU_RUN_BUDGET:-480}"
# step_limit WANT: WANT seconds, or what is left of the budget (less a margin
# for the step's own reporting) when that is less; 0 when nothing is left.
step_limit() {
  local left=$((budget - SECONDS - 5))
  if ((left < 10)); then echo 0; elif ((left < $1)); then echo "$left"; else echo "$1"; fi
}

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
# DIR/rayforge and DIR/rayforge_gpu_tests as they are (and DIR/librayforge.so
# for the profile step when the CLI does not load one).
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
# Also sets $card (the device's name) and $clocks (nvidia-smi's name, SM and
# memory clocks, CSV), printed once and kept in summary.txt and the JSON.
check_runtime() {
  { echo "== nvidia-smi"; nvidia-smi 2>&1; echo "== rayforge info --devices"; } >> "$summary"
  if command -v nvidia-smi > /dev/null; then
    clocks=$(nvidia-smi --query-gpu=name,clocks.sm,clocks.mem --format=csv 2>&1)
  else
    clocks="nvidia-smi not found"
  fi
  echo "$clocks"
  { echo "== nvidia-smi --query-gpu=name,clocks.sm,clocks.mem --format=csv"; echo "$clocks"; } >> "$summary"
  card=$(nvidia-smi --query-gpu=name --format=csv,noheader 2> /dev/null | head -1)
  local listing
  listing=$("$rf" info --devices 2>&1)
  echo "$listing" | tee -a "$summary"
  [[ -n "$card" ]] || card=$(sed -n 's/^cuda:[0-9]*  *\(.*\)$/\1/p' <<< "$listing" | head -1)
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

# step_tests [STEP FILTER LIMIT]: every gpu test (the tests step), or those
# of FILTER within LIMIT seconds (the changed step, appended to the same log).
step_tests() {
  local step=${1:-tests} filter=${2:-} limit=${3:-0} log="$out/gpu-tests.txt"
  if [[ -z "$filter" ]]; then
    (cd "$ROOT" && "$gpu_tests") > "$log" 2>&1
  else
    if [[ -n "$no_device" ]]; then
      report "$step" FAIL "not run: no CUDA device: $no_device"
      return
    fi
    if ((limit == 0)); then
      report "$step" UNAVAILABLE "out of the time budget (RAYFORGE_GPU_RUN_BUDGET=$budget s)"
      return
    fi
    local run="$scratch/tests-$step.txt"
    (cd "$ROOT" && timeout "$limit" "$gpu_tests" --gtest_filter="$filter") > "$run" 2>&1
    local status=$?
    { echo "== $step: --gtest_filter=$filter (exit $status)"; cat "$run"; } >> "$log"
    if ((status == 124)); then
      report "$step" FAIL "timed out after $limit s (gpu-tests.txt)"
      return
    fi
    log=$run
    (exit $status)
  fi
  local rc=$? passed skipped failures first
  passed=$(gtest_count "$log" PASSED) skipped=$(gtest_count "$log" SKIPPED) failures=$(gtest_count "$log" FAILED)
  passed=${passed:-0} skipped=${skipped:-0} failures=${failures:-0}
  local counts="$passed passed, $failures failed, $skipped skipped"
  if ((rc == 0 && skipped == 0 && passed > 0)); then
    report "$step" ok "$counts"
  elif ((rc == 0 && skipped > 0)); then
    report "$step" FAIL "$counts: a skipped gpu test tested nothing ($(grep -m1 -o 'no CUDA device: .*' "$log" || echo see gpu-tests.txt))"
  elif ((rc == 0)); then
    report "$step" FAIL "$counts: no test matched"
  else
    first=$(grep -m1 -o 'no CUDA device: .*' "$log" || grep -m1 -B1 '^\[  FAILED  \]' "$log" | head -1)
    report "$step" FAIL "$counts, exit $rc (${first:-see gpu-tests.txt})"
  fi
}

# The changed kernels' and builders' tests (issue 33): broad name patterns,
# so tests added under these names are picked up. The sanitizers take the
# new kernels' and builders' own tests and the two builder tests whose
# kernels hold shared-memory and warp code; GpuDeviceTracer's every-kernel
# tests (72 s and more under memcheck) and the brute-force hit checks (host
# work) run natively only.
changed_tests="${RAYFORGE_CHANGED_TESTS:-*AilaLaine*:*Cwbvh*:*Fma*:*Tracer*:*Hploc*:*HPloc*:*Treelet*:*Ploc*:*Hlbvh2*:*RawTree*:*Emit*:*LayoutConvert*:*DeviceBuild*:GpuBenchFigures.*:GpuProbe.*}"
changed_memcheck="${RAYFORGE_CHANGED_MEMCHECK:-*Fma*:*Hploc*:*Treelet*:*RawTree*:*Emit*:GpuPlocBuild.DeviceClusteringAndNodeBoxes:GpuHlbvh2Build.DeviceTopLevelIsTheCpuTopLevel:GpuBenchFigures.*:-*HitsEqualBruteForce*}"
changed_builders="${RAYFORGE_CHANGED_BUILDERS:-*Hploc*:*Treelet*:*RawTree*:*Emit*:GpuPlocBuild.DeviceClusteringAndNodeBoxes:GpuHlbvh2Build.DeviceTopLevelIsTheCpuTopLevel:-*HitsEqualBruteForce*}"

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

# step_sanitizer TOOL [STEP FILTER LIMIT]: TOOL over sanitizer_filter's
# selection within RAYFORGE_SANITIZER_TIMEOUT, or over FILTER within LIMIT
# seconds (the -changed steps; the probe's time counts against LIMIT too).
step_sanitizer() {
  local tool=$1 step=${2:-$1} log="$out/sanitizers.txt" limit="${4:-${RAYFORGE_SANITIZER_TIMEOUT:-150}}"
  if [[ -n "$no_device" ]]; then
    report "$step" FAIL "not run: no CUDA device: $no_device"
    return
  fi
  if ((limit == 0)); then
    report "$step" UNAVAILABLE "out of the time budget (RAYFORGE_GPU_RUN_BUDGET=$budget s)"
    return
  fi
  local started=$SECONDS
  local sanitizer
  sanitizer=$(command -v compute-sanitizer || ls /usr/local/cuda/bin/compute-sanitizer \
    /usr/local/cuda/compute-sanitizer/compute-sanitizer 2> /dev/null | head -1)
  if [[ -z "$sanitizer" ]]; then
    report "$step" UNAVAILABLE "compute-sanitizer not found (it ships with the CUDA toolkit)"
    return
  fi
  # A trivial run first: some sandboxed runtimes refuse the sanitizer ("device
  # not supported", then error 999 at the first allocation). That is the
  # runtime's limit, not a memory error of ours.
  local probe="$scratch/probe-$tool.txt"
  local probe_limit=$((limit < 120 ? limit : 120))
  (cd "$ROOT" && timeout "$probe_limit" "$sanitizer" --tool "$tool" --error-exitcode 3 "$gpu_tests" \
    --gtest_filter=GpuProbe.UploadLaunchDownload) > "$probe" 2>&1
  local rc=$?
  { echo "== $step: $tool probe (exit $rc)"; cat "$probe"; } >> "$log"
  if ((rc != 0)); then
    if grep -qiE 'not supported|error 999|cudaErrorUnknown|unknown error|unable to attach|injection' "$probe"; then
      report "$step" UNAVAILABLE "compute-sanitizer unavailable on this runtime ($(grep -m1 -iE 'not supported|999|unknown error|unable to attach|injection' "$probe" | cut -c1-160))"
    else
      report "$step" FAIL "the sanitizer's probe run failed, exit $rc (sanitizers.txt)"
    fi
    return
  fi
  local run="$scratch/run-$step.txt" filter=${3:-} why="RAYFORGE_SANITIZER_TIMEOUT"
  [[ -n "$filter" ]] || filter=$(sanitizer_filter "$tool")
  if [[ -n "${3:-}" ]]; then
    limit=$((limit - (SECONDS - started)))
    why="its share of RAYFORGE_GPU_RUN_BUDGET"
    ((limit >= 10)) || limit=10
  fi
  (cd "$ROOT" && timeout "$limit" "$sanitizer" --tool "$tool" --error-exitcode 3 "$gpu_tests" \
    --gtest_filter="$filter") > "$run" 2>&1
  rc=$?
  { echo "== $step: $tool on $filter (exit $rc)"; cat "$run"; } >> "$log"
  local errors
  errors=$(sed -n 's/.*ERROR SUMMARY: \([0-9]*\) error.*/\1/p' "$run" | tail -1)
  case $rc in
    0) report "$step" ok "ERROR SUMMARY: ${errors:-0} errors" ;;
    124) report "$step" FAIL "timed out after $limit s ($why)" ;;
    3) report "$step" FAIL "${errors:-some} errors reported (sanitizers.txt)" ;;
    *) report "$step" FAIL "a test failed under the sanitizer, exit $rc (sanitizers.txt)" ;;
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

# ---- The A/B and profile steps (issue 33): one call, old and new variants
# side by side, each run under its own timeout cut to the budget, results
# written under $out as each run ends.

# The A/B's kernels this binary knows: the old ones and their new variants.
ab_kernels() {
  local listing kernel known=()
  listing=$("$rf" bench --list 2> /dev/null)
  for kernel in aila-laine aila-laine-fma cwbvh cwbvh-fma; do
    grep -qE "^  $kernel  \(traces" <<< "$listing" && known+=("$kernel")
  done
  (IFS=,; echo "${known[*]}")
}

# A JSON string of $1 (other control characters than tab and newline dropped).
json_string() {
  local text
  text=$(printf '%s' "$1" | tr -d '\000-\010\013-\037')
  text=${text//\\/\\\\}
  text=${text//\"/\\\"}
  text=${text//$'\t'/\\t}
  text=${text//$'\r'/}
  printf '"%s"' "${text//$'\n'/\\n}"
}

# ab.json: the card, its clocks and every run so far (a bench's own JSON, or
# a command's text output), rewritten after each run.
ab_runs=()
write_ab_json() {
  local entry name kind file first=1
  {
    printf '{"tool": "scripts/gpu-run.sh ab", "card": %s, "clocks": %s, "date": "%s", "runs": [' \
      "$(json_string "${card:-}")" "$(json_string "${clocks:-}")" "$(date -u +%Y-%m-%dT%H:%M:%SZ)"
    for entry in "${ab_runs[@]}"; do
      IFS='|' read -r name kind file <<< "$entry"
      ((first)) || printf ', '
      first=0
      printf '{"name": %s, ' "$(json_string "$name")"
      if [[ "$kind" == json ]]; then
        printf '"bench": '
        cat "$file"
      else
        printf '"text": %s' "$(json_string "$(cat "$file")")"
      fi
      printf '}'
    done
    printf ']}\n'
  } > "$out/ab.json"
}

# ab_run NAME WANT COMMAND...: COMMAND (a rayforge bench with --json FILE
# placeholder "@JSON", or any command) within min(WANT, the budget left);
# its output appended to ab.txt, its JSON (or text) added to ab.json. Adds
# NAME to ab_failed when it fails, to ab_skipped when no time is left for it.
ab_failed=() ab_skipped=()
ab_run() {
  local name=$1 want=$2 limit
  shift 2
  limit=$(step_limit "$want")
  if ((limit == 0)); then
    echo "== $name: not run: out of the time budget" >> "$out/ab.txt"
    ab_skipped+=("$name")
    return
  fi
  local json="$scratch/ab-$name.json" text="$scratch/ab-$name.txt" args=() arg
  for arg in "$@"; do args+=("${arg//@JSON/$json}"); done
  rm -f "$json"
  echo "== $name (limit $limit s): ${args[*]}" >> "$out/ab.txt"
  timeout "$limit" "${args[@]}" > "$text" 2>&1
  local rc=$?
  cat "$text" >> "$out/ab.txt"
  ((rc == 0)) || ab_failed+=("$name ($( ((rc == 124)) && echo "timed out after $limit s" || echo "exit $rc"))")
  if [[ -s "$json" ]]; then ab_runs+=("$name|json|$json"); else ab_runs+=("$name|text|$text"); fi
  write_ab_json
}

step_ab() {
  if [[ -n "$no_device" ]]; then
    report ab FAIL "not run: no CUDA device: $no_device"
    return
  fi
  if (($(step_limit 30) == 0)); then
    report ab UNAVAILABLE "out of the time budget (RAYFORGE_GPU_RUN_BUDGET=$budget s)"
    return
  fi
  : > "$out/ab.txt"
  ab_runs=() ab_failed=() ab_skipped=()
  local kernels scenes=(--scene builtin:cornell) scenes_dir=() dragon="$ROOT/shared/scenes/stanford-dragon/dragon_vrip.ply"
  kernels=$(ab_kernels)
  [[ -n "$kernels" ]] || kernels=aila-laine,cwbvh
  if [[ -f "$ROOT/shared/scenes/views.json" ]]; then
    scenes_dir=(--scenes-dir "$ROOT/shared/scenes")
    scenes=("${scenes_dir[@]}" --scene sponza)
  fi
  {
    echo "gpu-run.sh ab: kernels $kernels on ${card:-an unnamed card}"
    echo "$clocks"
  } >> "$out/ab.txt"
  local rays=(--device cuda --gpu-kernel "$kernels" --rays "primary,diffuse" --res 1024x768 --embree none --reps 5
    --build-reps 1 --json @JSON)
  # Scanline and Morton primaries and diffuse rays, binned and SBVH trees.
  ab_run sponza-kernels 100 "$rf" bench "${scenes[@]}" --builder binned,sbvh "${rays[@]}"
  # Larger than L2: 15 Dragons (13.1M triangles), a 12M-triangle generated scene.
  if [[ -f "$dragon" ]]; then
    ab_run dragon-x15-kernels 75 "$rf" bench "${scenes_dir[@]}" --scene dragon-x15 --builder binned "${rays[@]}"
  else
    echo "== dragon-x15-kernels: not run: no $dragon (carry .gpu-scenes)" >> "$out/ab.txt"
  fi
  ab_run generated-12m-kernels 75 "$rf" bench "${scenes_dir[@]}" --scene generate:terrain-statues@12M \
    --builder binned "${rays[@]}"
  # The device builders on the Dragon: device time and time to first ray.
  if [[ -f "$dragon" ]]; then
    local treelets=("") builder variant
    "$rf" build --help 2>&1 | grep -q -- '--treelets' && treelets=("" --treelets)
    for builder in lbvh30 hlbvh2 ploc hploc; do
      for variant in "${treelets[@]}"; do
        ab_run "dragon-$builder${variant:+-treelets}" 20 "$rf" build "$dragon" --device cuda --builder "$builder" \
          ${variant:+"$variant"} --reps 5
      done
    done
  fi
  # Path tracing, depth 4: passes/s and the trace share per kernel.
  ab_run sponza-path 60 "$rf" bench "${scenes[@]}" --device cuda --gpu-kernel "$kernels" --integrator path \
    --max-depth 4 --res 1024x768 --reps 20 --json @JSON
  if ((${#ab_failed[@]} > 0)); then
    report ab FAIL "failed: ${ab_failed[*]}${ab_skipped:+; out of time: ${ab_skipped[*]}} (ab.txt)"
  elif ((${#ab_skipped[@]} > 0)); then
    report ab UNAVAILABLE "${#ab_runs[@]} runs; cut by the time budget: ${ab_skipped[*]} (ab.txt, ab.json)"
  else
    report ab ok "${#ab_runs[@]} runs, kernels $kernels (ab.txt, ab.json)"
  fi
}

# A CUDA tool: on PATH, else in the toolkit's and Nsight's usual folders
# (RAYFORGE_GPU_RUN_TOOL_DIRS, space-separated globs; "" for PATH alone).
find_tool() {
  local dirs dir
  dirs=${RAYFORGE_GPU_RUN_TOOL_DIRS-/usr/local/cuda/bin /usr/local/cuda/nsight-compute* /usr/local/cuda/nsight-systems*/bin /opt/nvidia/nsight-compute/* /opt/nvidia/nsight-systems/*/bin}
  command -v "$1" 2> /dev/null && return
  for dir in $dirs; do
    [[ -x "$dir/$1" ]] && { echo "$dir/$1"; return; }
  done
}

# The mangled names of the trace kernels in the resource-usage dump $1.
trace_kernel_names() {
  sed -n 's/^ *Function \([^ :]*\):.*/\1/p' "$1" |
    grep -E 'intersect_kernel|occluded_kernel|aila_laine_persistent|cwbvh_fma|extend_kernel|connect_kernel' | sort -u
}

# Per function of a SASS dump: loads from global (LDG) and local memory (LDL),
# local stores (STL), branches (BRA) and byte-select conversions (I2F), the
# review's (section 7a) counts.
sass_counts() {
  awk '/Function :/ { name = $3 }
       / LDG/ { ldg[name]++ } / LDL/ { ldl[name]++ } / STL/ { stl[name]++ } / BRA/ { bra[name]++ } / I2F/ { i2f[name]++ }
       / \/\*[0-9a-f]+\*\// { n[name]++ }
       END { for (f in n) printf "%-8d instr %5d LDG %5d LDL %5d STL %5d BRA %5d I2F  %s\n", n[f], ldg[f], ldl[f], stl[f], bra[f], i2f[f], f }' "$1"
}

# Nsight Compute's sections and metrics of the review's section 7(b).
ncu_sections=(LaunchStats Occupancy SchedulerStats WarpStateStats ComputeWorkloadAnalysis MemoryWorkloadAnalysis
  InstructionStats SourceCounters)
ncu_metrics=smsp__thread_inst_executed.sum,smsp__issue_active.avg.pct_of_peak_sustained_active,smsp__thread_inst_executed_per_inst_executed.ratio,smsp__average_warps_issue_stalled_long_scoreboard_per_issue_active.ratio,smsp__average_warps_issue_stalled_math_pipe_throttle_per_issue_active.ratio,smsp__average_warps_issue_stalled_wait_per_issue_active.ratio,smsp__average_warps_issue_stalled_lg_throttle_per_issue_active.ratio,smsp__average_warps_issue_stalled_no_instruction_per_issue_active.ratio,l1tex__t_sectors_pipe_lsu_mem_local_op_ld.sum,smsp__sass_inst_executed_op_local_ld.sum,l1tex__t_sector_hit_rate.pct,lts__t_sector_hit_rate.pct,dram__bytes_read.sum

step_profile() {
  if [[ -n "$no_device" ]]; then
    report profile FAIL "not run: no CUDA device: $no_device"
    return
  fi
  if (($(step_limit 30) == 0)); then
    report profile UNAVAILABLE "out of the time budget (RAYFORGE_GPU_RUN_BUDGET=$budget s)"
    return
  fi
  local log="$out/profile.txt" ran=() missing=() refused=() lib limit
  : > "$log"
  lib=$(ldd "$rf" 2> /dev/null | awk '/librayforge/ {print $3; exit}')
  [[ -z "$lib" && -f "${RAYFORGE_GPU_RUN_BINARIES:-/nonexistent}/librayforge.so" ]] && lib="$RAYFORGE_GPU_RUN_BINARIES/librayforge.so"
  echo "gpu-run.sh profile on ${card:-an unnamed card}; library ${lib:-not found}" >> "$log"
  echo "$clocks" >> "$log"
  local cuobjdump ncu nsys
  cuobjdump=$(find_tool cuobjdump) ncu=$(find_tool ncu) nsys=$(find_tool nsys)
  # (a) Registers, stack and spills of every kernel; the trace kernels' SASS.
  if [[ -n "$cuobjdump" && -n "$lib" ]]; then
    local usage="$scratch/resource-usage.txt" name
    limit=$(step_limit 60)
    if ((limit > 0)) && timeout "$limit" "$cuobjdump" --dump-resource-usage "$lib" > "$usage" 2>&1; then
      { echo "== cuobjdump --dump-resource-usage $lib"; cat "$usage"; } >> "$log"
      : > "$out/sass.txt"
      for name in $(trace_kernel_names "$usage"); do
        limit=$(step_limit 20)
        ((limit > 0)) || break
        timeout "$limit" "$cuobjdump" -sass -fun "$name" "$lib" >> "$out/sass.txt" 2>&1
      done
      { echo "== SASS counts per trace kernel (sass.txt)"; sass_counts "$out/sass.txt"; } >> "$log"
      ran+=(cuobjdump)
    else
      refused+=("cuobjdump ($(tail -1 "$usage" 2> /dev/null | cut -c1-100))")
    fi
  else
    missing+=(cuobjdump)
  fi
  # (b) Nsight Compute on one launch per kernel and ray set: the first timed
  # launch (--launch-skip 1 passes the warm-up), binned Sponza.
  if [[ -n "$ncu" ]]; then
    local kernel set scenes=(--scene builtin:cornell) sections=() section output
    [[ -f "$ROOT/shared/scenes/views.json" ]] && scenes=(--scenes-dir "$ROOT/shared/scenes" --scene sponza)
    for section in "${ncu_sections[@]}"; do sections+=(--section "$section"); done
    local kernels
    kernels=$(ab_kernels)
    # The review's pair first (aila-laine, cwbvh), then the new variants.
    for kernel in aila-laine cwbvh aila-laine-fma cwbvh-fma; do
      [[ ",$kernels," == *",$kernel,"* ]] || continue
      for set in primary diffuse; do
        limit=$(step_limit 60)
        ((limit > 0)) || break 2
        output="$scratch/ncu-$kernel-$set.txt"
        echo "== ncu: $kernel $set (limit $limit s)" >> "$log"
        timeout "$limit" "$ncu" --launch-skip 1 --launch-count 1 \
          -k 'regex:intersect_kernel|occluded_kernel|aila_laine|cwbvh' "${sections[@]}" --metrics "$ncu_metrics" \
          "$rf" bench "${scenes[@]}" --device cuda --gpu-kernel "$kernel" --builder binned --rays "$set" \
          --res 1024x768 --embree none --reps 1 --build-reps 1 --no-counts -q > "$output" 2>&1
        cat "$output" >> "$log"
        if grep -qE 'ERR_NVGPUCTRPERM|permission to access NVIDIA GPU Performance Counters' "$output"; then
          refused+=("ncu (no permission for the performance counters: ERR_NVGPUCTRPERM)")
          break 2
        fi
      done
    done
    grep -q '^== ncu' "$log" && ! grep -q 'ERR_NVGPUCTRPERM' "$log" && ran+=(ncu)
  else
    missing+=(ncu)
  fi
  # (d) Nsight Systems on the device builds of the Dragon: kernels, memcpys, gaps.
  local dragon="$ROOT/shared/scenes/stanford-dragon/dragon_vrip.ply"
  if [[ -n "$nsys" && -f "$dragon" ]]; then
    local builder
    for builder in lbvh30 hlbvh2 ploc hploc; do
      limit=$(step_limit 45)
      ((limit > 0)) || break
      echo "== nsys: build dragon --builder $builder (limit $limit s)" >> "$log"
      timeout "$limit" "$nsys" profile -t cuda --stats=true --force-overwrite true -o "$scratch/nsys-$builder" \
        "$rf" build "$dragon" --device cuda --builder "$builder" --reps 1 >> "$log" 2>&1
    done
    ran+=(nsys)
  elif [[ -z "$nsys" ]]; then
    missing+=(nsys)
  fi
  local result="ran: ${ran[*]:-none}${missing:+; not found: ${missing[*]}}${refused:+; refused: ${refused[*]}}"
  ((SECONDS < budget)) || result+="; cut by the time budget"
  if ((${#ran[@]} > 0)); then report profile ok "$result (profile.txt, sass.txt)"; else report profile UNAVAILABLE "$result"; fi
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
      changed) step_tests changed "$changed_tests" "$(step_limit 90)" ;;
      memcheck-changed) step_sanitizer memcheck "$step" "$changed_memcheck" "$(step_limit 90)" ;;
      racecheck-changed) step_sanitizer racecheck "$step" "$changed_builders" "$(step_limit 45)" ;;
      synccheck-changed) step_sanitizer synccheck "$step" "$changed_builders" "$(step_limit 40)" ;;
      ab) step_ab ;;
      profile) step_profile ;;
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
