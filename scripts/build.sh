#!/usr/bin/env bash
# Configures and builds rayforge (Release) into ./build (or $RAYFORGE_BUILD_DIR).
# The CUDA backend is built when nvcc is found; configure says so in one line.
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir="${RAYFORGE_BUILD_DIR:-build}"
jobs="${RAYFORGE_JOBS:-$(nproc)}"
# The Python module is built for the interpreter that has numpy and pybind11:
# Debian's /usr/bin/python3 (a python3 earlier on PATH, e.g. pyenv's, may lack them).
python_args=()
if [ -x /usr/bin/python3 ]; then python_args=(-DPython3_EXECUTABLE=/usr/bin/python3); fi
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release "${python_args[@]}" "$@" | grep -E "^-- rayforge|Error|error" || true
cmake --build "$build_dir" -j "$jobs"
