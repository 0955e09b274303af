#!/usr/bin/env bash
# Configures and builds rayforge (Release) into ./build (or $RAYFORGE_BUILD_DIR).
# The CUDA backend is built when nvcc is found; configure says so in one line.
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir="${RAYFORGE_BUILD_DIR:-build}"
jobs="${RAYFORGE_JOBS:-$(nproc)}"
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release "$@" | grep -E "^-- rayforge|Error|error" || true
cmake --build "$build_dir" -j "$jobs"
