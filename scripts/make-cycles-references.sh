#!/usr/bin/env bash
# Renders the Cycles reference images of tests/data/cycles (not part of CI):
# every SCENE.json there, twice (seeds 1 and 2), to SCENE.cycles-1.exr and
# SCENE.cycles-2.exr next to it. Installs Debian's blender when missing
# (needs root and the package registry). The settings and the material
# mapping are in scripts/cycles_reference.py and docs/rendering.md.
#
#   scripts/make-cycles-references.sh [SPP] [SCENE ...]   (default 2048 spp, every scene)
set -euo pipefail
cd "$(dirname "$0")/.."
spp=${1:-2048}
shift || true
if ! command -v blender >/dev/null; then
    echo "make-cycles-references: installing blender (Debian package)" >&2
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends blender >/dev/null
fi
blender --version | head -1
dir=tests/data/cycles
scenes=("$@")
if [ ${#scenes[@]} -eq 0 ]; then
    for f in "$dir"/*.json; do scenes+=("$(basename "$f" .json)"); done
fi
for name in "${scenes[@]}"; do
    for seed in 1 2; do
        out="$dir/$name.cycles-$seed.exr"
        start=$(date +%s)
        blender -b --factory-startup -noaudio --python-exit-code 1 -P scripts/cycles_reference.py -- \
            "$dir/$name.json" "$out" "$seed" "$spp" >"/tmp/cycles-$name-$seed.log" 2>&1 ||
            { echo "make-cycles-references: $name seed $seed failed; see /tmp/cycles-$name-$seed.log" >&2; exit 1; }
        echo "$name seed $seed: $spp spp, $(( $(date +%s) - start )) s -> $out"
    done
done
