#!/usr/bin/env bash
# System packages displace needs beyond a Rust toolchain: Mesa's software
# Vulkan (lavapipe) so the GPU path runs and is tested on machines without a
# GPU, Xvfb so the viewer's window is tested without a display, and Slurm
# with munge for the render-farm test.
# Idempotent; uses sudo only when not root.
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
need=()
dpkg -s mesa-vulkan-drivers >/dev/null 2>&1 || need+=(mesa-vulkan-drivers)
dpkg -s libvulkan1 >/dev/null 2>&1 || need+=(libvulkan1)
# `displace view` and its tests: a virtual X server, and the X client
# libraries winit loads at run time.
for p in xvfb libx11-6 libx11-xcb1 libxcursor1 libxrandr2 libxi6 libxkbcommon-x11-0; do
  dpkg -s "$p" >/dev/null 2>&1 || need+=("$p")
done
# The farm test (scripts/slurm-local.sh): a throwaway one-node Slurm.
for p in slurmctld slurmd slurm-client munge iproute2; do
  dpkg -s "$p" >/dev/null 2>&1 || need+=("$p")
done
# The Python package's tests: an interpreter that can make a virtual
# environment (Debian splits venv and pip out of python3).
command -v python3 >/dev/null 2>&1 || need+=(python3)
python3 -c "import ensurepip, venv" >/dev/null 2>&1 || need+=(python3-venv python3-pip)
if [ ${#need[@]} -gt 0 ]; then
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${need[@]}"
fi
