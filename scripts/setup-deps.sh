#!/usr/bin/env bash
# Installs rayforge's build and test dependencies from Debian 12 packages.
# Idempotent: installs only what is missing and refreshes the package lists
# only when something must be installed. Needs root (or sudo).
set -euo pipefail

packages=(
  build-essential cmake pkg-config git python3
  ccache                         # compiler cache for the Release, sanitizer and fuzz builds
  libtbb-dev                     # task-parallel builds and rendering
  libtinyobjloader-dev           # OBJ + MTL
  libtinygltf-dev                # glTF 2.0 / GLB
  libstb-dev                     # PNG/TGA/BMP/HDR decoding, PNG writing
  libjpeg62-turbo-dev            # JPEG decoding (libjpeg-turbo)
  libtinyexr-dev                 # EXR
  nlohmann-json3-dev             # JSON scene files
  libcli11-dev                   # command line
  libgtest-dev libgmock-dev      # tests
  libbenchmark-dev               # micro-benchmarks
  libembree-dev                  # optional benchmark peer (Embree 3)
  libzstd-dev                    # compressed geometry pages
  libmeshoptimizer-dev           # paged scenes' page codec (meshopt vertex and index codecs before zstd)
  liburing-dev                   # paged scenes' page reads through io_uring (optional: a reader pool otherwise)
  clang libclang-rt-14-dev       # libFuzzer targets and sanitizer runtimes (scripts/fuzz.sh)
  zlib1g-dev                     # tinyexr compiled into the fuzzers needs zlib.h
  python3-matplotlib             # charts of `rayforge bench --json` (scripts/plot-bench.py)
  libglfw3-dev libgl-dev         # the viewer's window and OpenGL 3.3 context (`rayforge view`)
  libimgui-dev                   # its controls panel (Dear ImGui 1.86 with the GLFW and OpenGL 3 backends)
  xvfb xauth libgl1-mesa-dri     # headless viewer tests: a virtual X server and Mesa's software OpenGL,
  xdotool                        #   and real mouse and key events sent to the window
  python3-dev pybind11-dev       # the Python module (`import rayforge`), built against /usr/bin/python3
  python3-numpy                  # its arrays
  libdlpack-dev                  # its CUDA arrays by DLPack (__dlpack__), with __cuda_array_interface__
  python3-pytest python3-hypothesis   # its tests, randomized arguments included
  python3-venv python3-pip python3-setuptools python3-wheel   # `pip install .` into a virtual environment (install test)
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup-deps: all ${#packages[@]} packages already installed"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "setup-deps: installing ${missing[*]}"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "setup-deps: done"
