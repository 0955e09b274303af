#!/usr/bin/env bash
# On a CUDA machine without package access (the device machine): runs the
# gpu tests and the GPU benchmarks of issues 6 and 7, writing everything to
# $OUT (or ./gpu-out).
#   scripts/gpu-run.sh [tests|bench|builds|memcheck|all]   (default all;
#   memcheck runs some gpu tests under compute-sanitizer; builds times every
#   device builder on the Stanford Dragon and on 2 and 15 copies of it, the
#   sizes of seed 000's table 5.1, when shared/scenes is there)
# Binaries: those staged in .gpu-prebuilt/ by scripts/gpu-prebuild.sh when
# they were built from these sources (carry .gpu-prebuilt: no build here);
# otherwise it unpacks .gpu-debs/ (scripts/gpu-bundle.sh) into a private
# prefix and builds the CLI and the gpu tests in build-gpu/. A cold build
# may not fit one 10-minute call: build-gpu/ stays while the machine is
# warm, so run the same command again.
set -uo pipefail
test_rc=0 bench_rc=0 path_rc=0 build_rc=0 builds_rc=0
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
what="${1:-all}"
out="${OUT:-$ROOT/gpu-out}"
mkdir -p "$out"
# At most 8 files come back from a device call: $out holds only the logs
# (nvidia-smi.txt, build.txt, gpu-tests.txt or memcheck.txt, bench-rays.txt
# and .json, bench-path.txt, bench-seed000.txt, builds.txt); the rest goes here.
scratch=$(mktemp -d)
# The digest of the sources the binaries come from (no git on the device).
source_digest() {
  (cd "$ROOT" && find src include apps bench tests cmake CMakeLists.txt -type f | LC_ALL=C sort | xargs sha1sum | sha1sum | cut -d' ' -f1)
}
prebuilt="$ROOT/.gpu-prebuilt"
nvidia-smi > "$out/nvidia-smi.txt" 2>&1
# Scenes staged by gpu-prebuild.sh: unpacked where the bench looks for them.
if [[ -d "$ROOT/.gpu-scenes" && ! -f "$ROOT/shared/scenes/views.json" ]]; then
  mkdir -p "$ROOT/shared/scenes"
  cp "$ROOT/.gpu-scenes/views.json" "$ROOT/shared/scenes/"
  (cd "$ROOT/.gpu-scenes" && find . -name '*.gz') | while read -r packed; do
    mkdir -p "$ROOT/shared/scenes/$(dirname "$packed")"
    gunzip -c "$ROOT/.gpu-scenes/$packed" > "$ROOT/shared/scenes/${packed%.gz}"
  done
  echo "gpu-run.sh: scenes unpacked from .gpu-scenes into shared/scenes"
fi
if [[ -x "$prebuilt/bin/rayforge" && -f "$prebuilt/SOURCES" && "$(cat "$prebuilt/SOURCES")" == "$(source_digest)" ]]; then
  echo "gpu-run.sh: using the binaries of .gpu-prebuilt (built from these sources)"
  export LD_LIBRARY_PATH="$prebuilt/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  rf="$prebuilt/bin/rayforge"
  gpu_tests="$prebuilt/bin/rayforge_gpu_tests"
else
  [[ -d "$prebuilt" ]] && echo "gpu-run.sh: .gpu-prebuilt was built from other sources: building here"
  prefix=/tmp/rayforge-debs
  mkdir -p "$prefix"
  shopt -s nullglob
  debs=("$ROOT"/.gpu-debs/*.deb)
  if ((${#debs[@]} == 0)); then
    echo "gpu-run.sh: no packages in $ROOT/.gpu-debs: run scripts/gpu-bundle.sh (or scripts/gpu-prebuild.sh) here and carry the folder" >&2
    exit 2
  fi
  for f in "${debs[@]}"; do dpkg-deb -x "$f" "$prefix" || { echo "gpu-run.sh: cannot unpack $f" >&2; exit 2; }; done
  lib="$prefix/usr/lib/x86_64-linux-gnu"
  export CMAKE_PREFIX_PATH="$prefix/usr:$lib/cmake${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
  # Multiarch headers (libjpeg's jconfig.h) live one level down.
  export CPATH="$prefix/usr/include:$prefix/usr/include/x86_64-linux-gnu${CPATH:+:$CPATH}"
  export LIBRARY_PATH="$lib${LIBRARY_PATH:+:$LIBRARY_PATH}"
  export LD_LIBRARY_PATH="$lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  export PATH="$prefix/usr/bin:$PATH"
  # .pc files say prefix=/usr: the sysroot puts the unpacked tree in front.
  export PKG_CONFIG_PATH="$lib/pkgconfig:$prefix/usr/share/pkgconfig"
  export PKG_CONFIG_SYSROOT_DIR="$prefix"
  build="$ROOT/build-gpu"
  {
    cmake -S "$ROOT" -B "$build" -DCMAKE_BUILD_TYPE=Release -DRAYFORGE_BUILD_BENCHMARKS=OFF \
      -DCMAKE_CUDA_ARCHITECTURES=90 &&
    cmake --build "$build" -j"$(nproc)" --target rayforge_cli rayforge_gpu_tests
  } > "$out/build.txt" 2>&1 || { tail -40 "$out/build.txt"; exit 1; }
  rf="$build/bin/rayforge"
  gpu_tests=$(find "$build" -name rayforge_gpu_tests -type f | head -1)
fi
"$rf" info --devices | tee -a "$out/nvidia-smi.txt"

if [[ "$what" == all || "$what" == tests ]]; then
  # The gpu-labelled tests are this one binary's.
  (cd "$ROOT" && "$gpu_tests") > "$out/gpu-tests.txt" 2>&1
  test_rc=$?
  echo "gpu tests: rc=$test_rc"; tail -15 "$out/gpu-tests.txt"
fi
if [[ "$what" == memcheck ]]; then
  # Device memory errors and races (compute-sanitizer ships with the toolkit).
  compute-sanitizer --tool memcheck --error-exitcode 3 "$gpu_tests" \
    --gtest_filter='GpuDeviceTracer.*:GpuRenderer.AovsAndCallbacks:GpuRenderer.RaySortingChangesNothing' \
    > "$out/memcheck.txt" 2>&1
  test_rc=$?
  echo "memcheck: rc=$test_rc"; tail -15 "$out/memcheck.txt"
fi
if [[ "$what" == all || "$what" == bench ]]; then
  scenes=(--scene builtin:cornell)
  [[ -d "$ROOT/shared/scenes" ]] && scenes=(--scenes-dir "$ROOT/shared/scenes" --scene sponza)
  "$rf" bench "${scenes[@]}" --device cuda --gpu-kernel all --rays primary,diffuse,shadow,ao --embree none \
    --reps 5 --json "$out/bench-rays.json" > "$out/bench-rays.txt" 2>&1
  bench_rc=$?
  echo "bench rays: rc=$bench_rc"; tail -25 "$out/bench-rays.txt"
  "$rf" bench "${scenes[@]}" --device cuda --integrator path --max-depth 4 --res 1024x768 --reps 20 \
    > "$out/bench-path.txt" 2>&1
  path_rc=$?
  echo "bench path: rc=$path_rc"; tail -8 "$out/bench-path.txt"
  # Seed 000's builders: GPU rows and the device LBVH's stage breakdown (issue 7).
  "$rf" bench --preset seed000 "${scenes[@]}" --device cuda --embree none > "$out/bench-seed000.txt" 2>&1
  build_rc=$?
  echo "bench seed000: rc=$build_rc"; tail -8 "$out/bench-seed000.txt"
fi
if [[ "$what" == all || "$what" == builds ]]; then
  # Issue 7's targets: 871K (Dragon), 1.74M (2 dragons; the table's 1.76M)
  # and 13.1M (15 dragons; the table's 12.7M) triangles.
  dragon="$ROOT/shared/scenes/stanford-dragon/dragon_vrip.ply"
  if [[ -f "$dragon" ]]; then
    for copies in 1 2 15; do
      scene="$scratch/dragon-x$copies.json"
      {
        printf '{"meshes": ['
        for ((i = 0; i < copies; ++i)); do
          ((i > 0)) && printf ', '
          printf '{"file": "%s", "transform": {"translate": [%d, 0, 0]}}' "$dragon" $((i * 1))
        done
        printf ']}\n'
      } > "$scene"
      for builder in lbvh30 lbvh63 hlbvh2 ploc gridbvh gridbvh-split; do
        "$rf" build "$scene" --device cuda --builder "$builder" --reps 5 --convert cwbvh \
          >> "$out/builds.txt" 2>&1 || builds_rc=1
      done
      "$rf" build "$scene" --device cuda --accel grid-proximity --reps 5 >> "$out/builds.txt" 2>&1 || builds_rc=1
      "$rf" build "$scene" --device cpu --builder sbvh --reps 1 >> "$out/builds.txt" 2>&1 || builds_rc=1
    done
    echo "builds: rc=$builds_rc"; grep -E "median|error" "$out/builds.txt"
  else
    echo "builds: skipped, no $dragon (copy the Stanford Dragon into shared/scenes)"
  fi
fi
# Non-zero when any step failed, so the caller sees it in the exit status.
exit $(( test_rc || bench_rc || path_rc || build_rc || builds_rc ))
