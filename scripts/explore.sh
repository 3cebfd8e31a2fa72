#!/usr/bin/env bash
# Explores new cases of the randomized tests, on purpose and apart from the
# test suite. The suite (scripts/test.sh, CI) runs every property test on the
# fixed seed of .cargo/config.toml, so a fresh clone passes every time; this
# script draws a fresh seed, runs many times the suite's cases of the
# properties of the tracers, the bake, the curved shells, the file
# parsers and the renders of random extreme scenes, and mutates the
# parsers' inputs from a fresh fuzz seed. Run it before resolving work on
# those parts.
#
#   scripts/explore.sh                 # fresh seeds, 16x the cases
#   SCALE=4000 scripts/explore.sh curved  # ~a million curved cases
#   SEED=1234 scripts/explore.sh       # repeat an exploration
#
# A failure prints proptest's minimal case and adds it to the test's
# `*.proptest-regressions` file (commit it: the suite then runs it first);
# the fuzz test keeps its crashing inputs under target/fuzz-crashes.
# Arguments name groups to run: tracers, bake, curved, parsers, scenes,
# python (all
# when none; python runs the Python package's tests on rays of fresh seeds,
# SCALE/4 times, through scripts/test-python.sh). Tests build in release,
# where the cases run fastest.
set -euo pipefail
cd "$(dirname "$0")/.."
seed="${SEED:-$(od -An -N4 -tu4 /dev/urandom | tr -d ' ')}"
scale="${SCALE:-16}"
groups=("$@")
[ ${#groups[@]} -gt 0 ] || groups=(tracers bake curved parsers scenes python)
fuzz_seed=$((seed % 1000000007))
fuzz_cases="${FUZZ_CASES:-10000}"
echo "explore: PROPTEST_RNG_SEED=$seed DISPLACE_PROPERTY_SCALE=$scale DISPLACE_FUZZ_SEED=$fuzz_seed DISPLACE_FUZZ_CASES=$fuzz_cases groups: ${groups[*]}"
export PROPTEST_RNG_SEED="$seed" DISPLACE_PROPERTY_SCALE="$scale"
export DISPLACE_FUZZ_SEED="$fuzz_seed" DISPLACE_FUZZ_CASES="$fuzz_cases"
run() { echo "explore: cargo test --release $*"; cargo test --release "$@"; }
for g in "${groups[@]}"; do
  case "$g" in
    tracers) run -p displace-core --test trace --test packet --test techniques --test pyramid --test horizon ;;
    bake) run -p displace-core --test conservative --lib -- edt normal_map ;;
    curved) run -p displace-render --test curved -- rays_never_cross_the_surface_before_their_hit ;;
    parsers) run -p displace-core --lib -- npy
             run -p displace-render --test fuzz ;;
    scenes) run -p displace-render --test extreme_scenes --test batch
            run -p displace-render --lib -- integrators::path::lanes ;;
    python) for k in $(seq 1 $(( (scale + 3) / 4 ))); do
              echo "explore: DISPLACE_PY_SEED=$((seed + k)) scripts/test-python.sh"
              DISPLACE_PY_SEED=$((seed + k)) bash scripts/test-python.sh
            done ;;
    *) echo "explore: unknown group '$g' (tracers, bake, curved, parsers, scenes, python)" >&2; exit 2 ;;
  esac
done
echo "explore: clean (seed $seed, scale $scale)"
