#!/usr/bin/env bash
# Prepares a GPU session: downloads the Debian packages the CUDA build and the
# gpu tests need into .gpu-debs/ (git-ignored, about 12 MB), for the device
# machine, which has no package access. Run here (with the package registry
# reachable); then run scripts/gpu-run.sh there with .gpu-debs carried along.
# Embree and Google Benchmark are left out: the device build needs neither.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$ROOT/.gpu-debs"
bundle="${BUNDLE_DEBS:-$ROOT/../shared/tools/bundle-debs.sh}"
[[ -x "$bundle" || -f "$bundle" ]] || { echo "gpu-bundle.sh: $bundle not found (set BUNDLE_DEBS)" >&2; exit 2; }
rm -rf "$out"
bash "$bundle" "$out" libtbb-dev libtinyobjloader-dev libtinygltf-dev libstb-dev libtinyexr-dev \
  nlohmann-json3-dev libcli11-dev libgtest-dev libjpeg62-turbo-dev pkg-config
# The C library's headers and the base system's libraries come with the
# device image; Debian's would shadow them (gpu-run.sh puts the bundle first
# on LD_LIBRARY_PATH for every process, cmake and nvcc included).
rm -f "$out"/libc6-dev_* "$out"/libc-dev-bin_* "$out"/linux-libc-dev_* "$out"/libcrypt-dev_* \
  "$out"/libnsl-dev_* "$out"/libtirpc-dev_* "$out"/libssl3_* "$out"/libgssapi-krb5-2_* "$out"/libk5crypto3_* \
  "$out"/libkrb5-3_* "$out"/libkrb5support0_* "$out"/libkeyutils1_* "$out"/libcom-err2_* "$out"/libnsl2_* \
  "$out"/libtirpc3_* "$out"/libtirpc-common_* "$out"/libudev1_* "$out"/rpcsvc-proto_*
echo "gpu-bundle.sh: $(ls "$out"/*.deb | wc -l) packages, $(du -sh "$out" | cut -f1) in $out"
