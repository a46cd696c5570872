#!/usr/bin/env bash
# The main job: sets up and builds, then runs avsplat end to end on the embedded default scene
# and writes its outputs (fused PLY, rendered PNGs, a summary) into the folder it names
# (default: out/demo).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${1:-$root/out/demo}"
bash "$root/scripts/setup.sh"
"$root/build/apps/avsplat" demo -o "$out"
