#!/usr/bin/env bash
# Bytes a unique triangle of a generated paged scene for every attribute
# format and page codec (docs/paged-scenes.md, "Page density"): one
# `rayforge generate` per combination, the sizes from its report.
#
#   scripts/page-density.sh [--rayforge BIN] [--scene NAME] [--triangles N] [--statues DIR] [--out FILE.md]
#
# Defaults: build-dev/bin/rayforge (else build/bin/rayforge), terrain-statues,
# 4M triangles, ../shared/scenes when present. Each file is written to a
# temporary folder and removed.
set -euo pipefail

here="$(cd "$(dirname "$0")/.." && pwd)"
bin="$here/build-dev/bin/rayforge"
[[ -x "$bin" ]] || bin="$here/build/bin/rayforge"
scene=terrain-statues
triangles=4M
statues=""
[[ -d "$here/../shared/scenes" ]] && statues="$here/../shared/scenes"
out=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --rayforge) bin="$2"; shift 2 ;;
    --scene) scene="$2"; shift 2 ;;
    --triangles) triangles="$2"; shift 2 ;;
    --statues) statues="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    -h|--help) sed -n '2,11p' "$0"; exit 0 ;;
    *) echo "page-density.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[[ -x "$bin" ]] || { echo "page-density.sh: no rayforge binary at $bin (build first, or --rayforge BIN)" >&2; exit 2; }

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
statue_args=()
[[ -n "$statues" ]] && statue_args=(--statues "$statues")

# attributes, codec, extra options
combos=(
  "full none"
  "full zstd"
  "compact none"
  "compact zstd"
  "compact meshopt"
  "full meshopt"
  "shared none"
  "shared zstd"
  "shared meshopt"
  "shared meshopt --zstd-level 9"
  "shared meshopt --attribute-page 4K"
  "shared meshopt --attribute-page 16K"
)
table="| attributes | codec | options | file | geometry | attributes | textures | bytes a unique triangle | write s |
|---|---|---|---:|---:|---:|---:|---:|---:|"
for combo in "${combos[@]}"; do
  read -r attributes codec extra <<<"$combo"
  extra_args=()
  [[ -n "${extra:-}" ]] && read -r -a extra_args <<<"$extra"
  line="$("$bin" generate "$scene" --triangles "$triangles" "${statue_args[@]}" -q --attributes "$attributes" \
            --codec "$codec" "${extra_args[@]}" -o "$tmp/scene.rfpack" | tail -n 1)"
  # "...| 24.07 MiB (geometry 6.95 MiB, attributes 16.16 MiB, textures 767.96 KiB, resident ...), 25.2 bytes a unique triangle | ... | 1.5 s (...)"
  row="$(printf '%s\n' "$line" | sed -E 's/.*\| ([0-9.]+ [KMG]?i?B) \(geometry ([0-9.]+ [KMG]?i?B), attributes ([0-9.]+ [KMG]?i?B), textures ([0-9.]+ [KMG]?i?B).*\), ([0-9.]+) bytes a unique triangle.*\| ([0-9.]+) s \(.*/\1|\2|\3|\4|\5|\6/')"
  IFS='|' read -r file geometry attr textures per_triangle seconds <<<"$row"
  table+="
| $attributes | $codec | ${extra:-} | $file | $geometry | $attr | $textures | **$per_triangle** | $seconds |"
  echo "$attributes $codec ${extra:-}: $per_triangle bytes a unique triangle" >&2
done
header="$scene, $triangles triangles$( [[ -n "$statues" ]] && echo ", statues from $statues"), $(date -u +%Y-%m-%d), $(nproc) cores"
if [[ -n "$out" ]]; then
  printf '%s\n\n%s\n' "$header" "$table" >"$out"
  echo "page-density.sh: wrote $out" >&2
else
  printf '%s\n\n%s\n' "$header" "$table"
fi
