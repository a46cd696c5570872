#!/usr/bin/env bash
# Installs PlayCanvas's splat-transform (the independent implementation that the format and
# reduction tests and reports compare with) into build-node/ at the repository root, an ignored
# folder, from the npm registry. Does nothing when that version is there already. Without npm it
# says so and exits 0: the tests that need the peer then skip, naming npm as the reason.
#   scripts/splat_transform.sh        -> prints the path of the splat-transform executable
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
version=3.7.0
dir="$root/build-node"
bin="$dir/node_modules/.bin/splat-transform"
if ! command -v npm >/dev/null 2>&1; then
  echo "npm not found: splat-transform $version is not installed; the tests that compare with it skip" >&2
  exit 0
fi
if ! { [ -x "$bin" ] && "$bin" --version 2>/dev/null | grep -q "v$version"; }; then
  mkdir -p "$dir"
  npm install --prefix "$dir" --no-audit --no-fund --loglevel=error "@playcanvas/splat-transform@$version" >&2
fi
echo "$bin"
