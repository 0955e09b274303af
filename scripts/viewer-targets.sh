#!/usr/bin/env bash
# The viewer's targets (docs/viewer.md), measured with its own statistics on Crytek
# Sponza (../shared/scenes), 640x360, Whitted with the views.json point light,
# 2 threads, under Xvfb with Mesa's software OpenGL:
#   still      frames per second at full resolution after 30 passes, and the
#              first image's time from launch (load + build + first pass)
#   moving     frames per second of the previews during a 3 s walk, and the
#              longest camera-change-to-image delay during it
#   orbit      one orbit step: its first image's delay
#   builders   switching to sbvh, ploc and a kd-tree: the longest the window
#              went without drawing (its own work per frame) while each built
# Prints one JSON line per measurement and run (print-stats), RUNS runs
# (default 3). Needs a build with the viewer and xvfb-run.
#   scripts/viewer-targets.sh [RUNS]
set -euo pipefail
cd "$(dirname "$0")/.."
runs="${1:-3}"
script="$(mktemp)"
trap 'rm -f "$script" "$script.json"' EXIT
cat >"$script" <<'SCRIPT'
wait-passes 30
print-stats
reset-stats
walk forward 3
print-stats
wait-passes 10
reset-stats
orbit 10 0
wait-frames 1
print-stats
wait-passes 10
reset-stats
set builder sbvh
wait-idle
wait-frames 1
print-stats
reset-stats
set builder ploc
wait-idle
wait-frames 1
print-stats
reset-stats
set accel kdtree
wait-idle
wait-frames 1
print-stats
quit
SCRIPT
for run in $(seq "$runs"); do
  xvfb-run -a -s "-screen 0 1280x1024x24" ./build/bin/rayforge view sponza --res 640x360 --integrator whitted \
    --threads 2 --script "$script" --bookmarks "$script.json" 2>/dev/null |
    awk -v run="$run" 'BEGIN { split("still moving orbit sbvh ploc kdtree", name, " ") }
                       { printf "{\"run\":%d,\"measure\":\"%s\",%s\n", run, name[NR], substr($0, 2) }'
done
