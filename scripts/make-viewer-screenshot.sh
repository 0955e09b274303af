#!/usr/bin/env bash
# The viewer's screenshot in docs/viewer.md and the README: Crytek Sponza
# (../shared/scenes) in `rayforge view` under Xvfb, panel and statistics
# shown, after 16 Whitted passes. Needs a build with the viewer and xvfb-run.
#   scripts/make-viewer-screenshot.sh [OUT.png]   (default docs/images/viewer.png)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-docs/images/viewer.png}"
script="$(mktemp)"
trap 'rm -f "$script"' EXIT
cat >"$script" <<SCRIPT
wait-passes 16
screenshot-window $out
quit
SCRIPT
xvfb-run -a -s "-screen 0 1400x900x24" ./build/bin/rayforge view sponza --res 960x540 --window 1280x720 \
  --integrator whitted --shading blinn --threads 2 --script "$script" --bookmarks "$script.json" 2>&1 | grep -v "warning" || true
echo "make-viewer-screenshot: wrote $out"
