#!/usr/bin/env bash
# ctest `python_install` (labels cpu;python;install): the installed artefacts
# work from anywhere.
#   1. cmake --install into a private prefix: its bin/rayforge and its Python
#      package, used from another folder, load the prefix's librayforge
#      (the RPATHs are relative to $ORIGIN).
#   2. python3 -m venv --system-site-packages + pip install --no-build-isolation
#      --no-index of the repository (pyproject.toml), packaging this build
#      folder (RAYFORGE_BUILD_DIR, so nothing compiles twice), used from
#      another folder: the module loads the venv's own copy of the library.
# usage: install_test.sh BUILD_DIR SOURCE_DIR WORK_DIR PYTHON
set -euo pipefail
build=$(cd "$1" && pwd) source=$(cd "$2" && pwd) work=$3 python=$4
rm -rf "$work" && mkdir -p "$work/elsewhere"
work=$(cd "$work" && pwd)
cd "$work/elsewhere"

# Imports rayforge with $1 as the interpreter, casts one ray, and checks
# that librayforge came from under $2.
check_module() {
    "$1" - "$2" <<'PY'
import sys
import numpy as np
import rayforge
scene = rayforge.RaycastingScene()
scene.add_triangles(np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], np.float32), np.array([[0, 1, 2]], np.uint32))
t = scene.cast_rays(np.array([[0, 0, 2, 0, 0, -1]], np.float32))["t_hit"]
assert abs(float(t[0]) - 2.0) < 1e-6, t
libs = {line.split()[-1] for line in open("/proc/self/maps") if "librayforge.so" in line}
assert libs and all(lib.startswith(sys.argv[1]) for lib in libs), f"librayforge from {libs}, not {sys.argv[1]}"
print(f"rayforge {rayforge.__version__} from {rayforge.__file__}, library {libs.pop()}")
PY
}

echo "== cmake --install into $work/prefix"
cmake --install "$build" --prefix "$work/prefix" >/dev/null
if [ -x "$work/prefix/bin/rayforge" ]; then
    "$work/prefix/bin/rayforge" --version
    "$work/prefix/bin/rayforge" render builtin:cornell --res 32x24 --spp 1 -o "$work/cornell.png" >/dev/null
    test -s "$work/cornell.png"
fi
package=$(find "$work/prefix" -path '*/rayforge/__init__.py' -printf '%h\n')
PYTHONPATH=$(dirname "$package") check_module "$python" "$work/prefix/"

echo "== venv + pip install --no-build-isolation --no-index $source"
"$python" -m venv --system-site-packages "$work/venv"
# pip builds in the source tree; setuptools' build folder goes to $work instead.
RAYFORGE_BUILD_DIR="$build" RAYFORGE_BUILD_BASE="$work/pip-build" \
    "$work/venv/bin/pip" install --quiet --no-build-isolation --no-index "$source"
"$work/venv/bin/pip" show rayforge >"$work/pip-show.txt" && head -2 "$work/pip-show.txt"
check_module "$work/venv/bin/python" "$work/venv/"
echo "python_install: OK"
