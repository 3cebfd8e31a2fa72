#!/usr/bin/env bash
# scripts/bench_farm.sh [SCENE [SIZE [SPP]]]: the measurements of
# BENCHMARKS.md, "Scale". One render on one machine (cold and warm bake
# cache), then the same image as N = 1, 2, 4, 8 tiles through a real Slurm
# (scripts/slurm-local.sh: one task per CPU, --threads 1 each), with the
# shared bake cache and without it (--no-cache: every task bakes). Prints
# wall times, per-tile render and set-up times, and the speed-ups.
# Defaults: the built-in seed scene (scenes/cornell_studded_shadows.toml),
# 1024x1024, 16 spp. DISPLACE names the binary (default target/release).
# At the issue's 4096x4096 and 64 spp every image is minutes of both cores;
# these pick the runs (space-separated, defaults as shown):
#   BENCH_FARM_RUNS="cold warm"        the one-machine renders
#   BENCH_FARM_SHARED_NS="1 2 4 8"     task counts with the shared bake cache
#   BENCH_FARM_NOCACHE_NS="1 2 4 8"    task counts where every task bakes
# and SLURM_LOCAL_TIMEOUT (scripts/slurm-local.sh's wait, default 900 s)
# must outlast a run: 2400 at that size.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
scene=$(realpath "${1:-$root/scenes/cornell_studded_shadows.toml}")
size=${2:-1024x1024} spp=${3:-16}
export DISPLACE=${DISPLACE:-$root/target/release/displace}
work=$(mktemp -d /tmp/bench-farm.XXXXXX)
trap 'rm -rf "$work"' EXIT
now() { date +%s.%N; }
secs() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", b - a }'; }
# The summary line's "setup X s" and "render Y s", summed over files.
times() { grep -ho 'setup [0-9.]* s\|render [0-9.]* s' "$@" | awk '
  /setup/ { s += $2; ns++ } /render/ { r += $2; if ($2 > rmax) rmax = $2; nr++ }
  END { printf "setup %.2f s/task, render %.2f s/tile (max %.2f)", s / ns, r / nr, rmax }'; }

echo "scene $(basename "$scene") at $size, $spp spp; $(nproc) CPUs; load $(cut -d' ' -f1-3 /proc/loadavg)"
for run in ${BENCH_FARM_RUNS:-cold warm}; do
  [ $run = cold ] && rm -rf "$work/cache1"
  t0=$(now)
  DISPLACE_CACHE=$work/cache1 "$DISPLACE" render -q "$scene" --size "$size" --spp "$spp" -o "$work/one.png" 2>"$work/one.log"
  t1=$(now)
  echo "one machine, 2 threads, $run cache: $(secs "$t0" "$t1") s wall; $(times "$work/one.log")"
done
[ -n "${BENCH_FARM_NO_SLURM:-}" ] && exit 0
for cache in shared none; do
  ns=${BENCH_FARM_SHARED_NS:-1 2 4 8}
  [ $cache = none ] && ns=${BENCH_FARM_NOCACHE_NS:-1 2 4 8}
  for n in $ns; do
    rm -rf "$work/out" "$work/logs" "$work/cache"
    extra="--size $size --spp $spp"
    [ $cache = none ] && extra="$extra --no-cache"
    t0=$(now)
    DISPLACE_ARGS=$extra DISPLACE_CACHE=$work/cache SLURM_LOCAL_LOGS=$work/logs \
      bash "$root/scripts/slurm-local.sh" "$scene" "$n" "$work/out" >"$work/slurm.log"
    t1=$(now)
    cmp -s "$work/out/image.png" "$work/one.png" || { echo "N=$n: merged image differs from the single render" >&2; exit 1; }
    echo "N=$n tasks, $cache cache: $(grep -o 'completed in [0-9.]* s' "$work/slurm.log") (script $(secs "$t0" "$t1") s with daemon start); $(times "$work"/logs/task_*.out)"
  done
done
