#!/usr/bin/env bash
# Runs the whole test suite of a build (./build by default). GPU-labelled
# tests skip with a message when no CUDA device is present.
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir="${RAYFORGE_BUILD_DIR:-build}"
ctest --test-dir "$build_dir" --output-on-failure -j "$(nproc)" "$@"
