#!/usr/bin/env bash
# Renders every scene under scenes/ into docs/gallery/ (PNG) and prints a
# Markdown table of render times for the README; then each Cornell box again
# with the path tracer (`--integrator path`, PATH_SPP samples per pixel,
# default 128) into docs/gallery/path/, and a table of both side by side.
# Usage:
#   bash scripts/render_gallery.sh [SIZE]      (default 384x384)
set -euo pipefail
cd "$(dirname "$0")/.."
size="${1:-384x384}"
path_spp="${PATH_SPP:-128}"
cargo build --release --bin displace -q
exe="${CARGO_TARGET_DIR:-target}/release/displace"
mkdir -p docs/gallery/path
echo "| scene | image | wall time |"
echo "|---|---|---|"
for scene in scenes/*.toml; do
  name="$(basename "$scene" .toml)"
  start=$EPOCHREALTIME
  "$exe" render "$scene" --size "$size" -o "docs/gallery/$name.png" >/dev/null 2>&1
  end=$EPOCHREALTIME
  awk -v n="$name" -v a="$start" -v b="$end" 'BEGIN { printf "| `%s` | ![%s](docs/gallery/%s.png) | %.1f s |\n", n, n, n, b - a }'
done
echo
echo "| scene | whitted (with its fill light) | path, $path_spp spp (no fill light) | path wall time |"
echo "|---|---|---|---|"
for scene in scenes/cornell_*.toml; do
  name="$(basename "$scene" .toml)"
  start=$EPOCHREALTIME
  "$exe" render "$scene" --size "$size" --integrator path --spp "$path_spp" \
    -o "docs/gallery/path/$name.png" >/dev/null 2>&1
  end=$EPOCHREALTIME
  awk -v n="$name" -v a="$start" -v b="$end" 'BEGIN { printf "| `%s` | ![%s](docs/gallery/%s.png) | ![%s, path](docs/gallery/path/%s.png) | %.1f s |\n", n, n, n, n, n, b - a }'
done
