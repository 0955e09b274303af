#!/usr/bin/env bash
# Prepares a GPU session without a build on the device: compiles the CLI and
# the gpu tests here for sm_90 (H100 / H200), host code for x86-64-v3 (AVX2 +
# FMA, which every H100/H200 host has; not -march=native: the device
# machine's CPU may differ; and not baseline x86-64, whose host code would
# take the non-FMA branch of src/trace/triangle_intersect.h while the device
# takes the FMA one, breaking the bit-exact comparisons), no Embree (the
# device runs use --embree none) and no viewer window (the device machine has
# no display; the display kernel is in the gpu tests), and stages them with the shared libraries
# they need into .gpu-prebuilt/ (git-ignored, about 40 MB: it fits the
# device call's carry limit). A cold build on the device takes longer than
# one 10-minute call (renderer.cu alone compiles for well over 5 minutes).
# Also stages compressed benchmark scenes in .gpu-scenes/ (about 14 MB).
# Then, on the device: scripts/gpu-run.sh [STEP...] (no step: the one-call
# order, changed tests, their sanitizers, ab and profile, within 8 minutes;
# docs/gpu.md) with .gpu-prebuilt and .gpu-scenes carried (ab's larger-than-L2
# scenes need nothing more: dragon-x15 copies the staged Dragon and
# generate:terrain-statues@12M is generated there); it uses the staged binaries when they were
# built from the sources it finds there (a digest of src, include, apps,
# bench, tests and the CMake files), else it builds.
#   scripts/gpu-prebuild.sh            (build folder: build-gpu-prebuilt/)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$ROOT/build-gpu-prebuilt"
stage="$ROOT/.gpu-prebuilt"
jobs="${RAYFORGE_JOBS:-$(nproc)}"
command -v nvcc > /dev/null || { echo "gpu-prebuild.sh: nvcc not found: the CUDA backend cannot be built here" >&2; exit 2; }
start=$(date +%s)
sources=$(cd "$ROOT" && find src include apps bench tests cmake CMakeLists.txt -type f | LC_ALL=C sort | xargs sha1sum |
  sha1sum | cut -d' ' -f1)
cmake -S "$ROOT" -B "$build" -DCMAKE_BUILD_TYPE=Release -DRAYFORGE_NATIVE=OFF -DRAYFORGE_MARCH=x86-64-v3 -DRAYFORGE_BUILD_BENCHMARKS=OFF \
  -DCMAKE_CUDA_ARCHITECTURES=90 -DCMAKE_DISABLE_FIND_PACKAGE_embree=TRUE -DRAYFORGE_ENABLE_VIEWER=OFF > /dev/null
cmake --build "$build" -j "$jobs" --target rayforge_cli rayforge_gpu_tests
# The Python module too, where this build has it (gpu-run.sh's python step).
if cmake --build "$build" --target help | grep -q "_rayforge$"; then
  cmake --build "$build" -j "$jobs" --target _rayforge
fi
rf="$build/bin/rayforge"
gpu_tests=$(find "$build" -name rayforge_gpu_tests -type f | head -1)
[[ -x "$rf" && -n "$gpu_tests" ]] || { echo "gpu-prebuild.sh: the build did not produce both binaries" >&2; exit 1; }

rm -rf "$stage"
mkdir -p "$stage/bin" "$stage/lib"
cp "$rf" "$gpu_tests" "$stage/bin/"
# Every shared library the two binaries load (copied under the names the
# loader asks for), except the C and C++ runtimes and the driver, which come
# with the device image.
for binary in "$stage/bin/rayforge" "$stage/bin/rayforge_gpu_tests"; do
  ldd "$binary" | awk '/=> \// {print $3}'
done | sort -u | while read -r library; do
  case "$(basename "$library")" in
    libc.so* | libm.so* | libstdc++.so* | libgcc_s.so* | libdl.so* | libpthread.so* | librt.so* | libcuda.so*) ;;
    *) cp -L "$library" "$stage/lib/" ;;
  esac
done
if compgen -G "$build/python/rayforge/_rayforge*.so" > /dev/null; then
  mkdir -p "$stage/python"
  cp -r "$build/python/rayforge" "$stage/python/"
fi
# What gpu-run.sh checks before using them: the digest of the sources,
# taken before the build (the device's copy of the checkout has no git),
# and, for people, the commit.
echo "$sources" > "$stage/SOURCES"
git -C "$ROOT" rev-parse HEAD > "$stage/COMMIT" 2> /dev/null || true
echo "gpu-prebuild.sh: $(du -sh "$stage" | cut -f1) in $stage ($(ls "$stage/lib" | wc -l) libraries), $(($(date +%s) - start)) s"

# The benchmark scenes, compressed to fit the carry limit with the binaries:
# Crytek Sponza without its textures (they do not change ray throughput and
# would not fit) and the Stanford Dragon, with views.json. gpu-run.sh unpacks
# them into shared/scenes on the device.
scenes="${RAYFORGE_SCENES:-$ROOT/../shared/scenes}"
if [[ -f "$scenes/views.json" ]]; then
  rm -rf "$ROOT/.gpu-scenes"
  mkdir -p "$ROOT/.gpu-scenes"
  cp "$scenes/views.json" "$ROOT/.gpu-scenes/"
  for file in crytek-sponza/sponza.obj crytek-sponza/sponza.mtl stanford-dragon/dragon_vrip.ply; do
    if [[ -f "$scenes/$file" ]]; then
      mkdir -p "$ROOT/.gpu-scenes/$(dirname "$file")"
      gzip -c -6 "$scenes/$file" > "$ROOT/.gpu-scenes/$file.gz"
    fi
  done
  echo "gpu-prebuild.sh: $(du -sh "$ROOT/.gpu-scenes" | cut -f1) of scenes in $ROOT/.gpu-scenes (carry it too)"
else
  echo "gpu-prebuild.sh: no $scenes/views.json: no scenes staged (the bench falls back to built-in scenes)"
fi
