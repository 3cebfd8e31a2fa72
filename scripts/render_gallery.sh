#!/usr/bin/env bash
# Renders every scene under scenes/ into docs/gallery/ (PNG) and prints a
# Markdown table of render times for the README. Usage:
#   bash scripts/render_gallery.sh [SIZE]      (default 384x384)
set -euo pipefail
cd "$(dirname "$0")/.."
size="${1:-384x384}"
cargo build --release --bin displace -q
mkdir -p docs/gallery
echo "| scene | image | wall time |"
echo "|---|---|---|"
for scene in scenes/*.toml; do
  name="$(basename "$scene" .toml)"
  start=$EPOCHREALTIME
  ./target/release/displace render "$scene" --size "$size" -o "docs/gallery/$name.png" >/dev/null 2>&1
  end=$EPOCHREALTIME
  awk -v n="$name" -v a="$start" -v b="$end" 'BEGIN { printf "| `%s` | ![%s](docs/gallery/%s.png) | %.1f s |\n", n, n, n, b - a }'
done
