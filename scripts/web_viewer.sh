#!/usr/bin/env bash
# Installs the web viewer that `avsplat view`, `.html` output and avsplat.show() use: Spark
# (World Labs' Gaussian-splat renderer on three.js) and three.js, pinned, from the npm registry
# into build-node/viewer/ (an ignored folder), then bundles them with web/viewer.js into one
# module, build-node/viewer/dist/avsplat-viewer.js, next to the page template web/viewer.html.
# Also installs playwright-core (pinned), with which the browser tests drive Debian's chromium.
# Nothing of it is committed; the pages it makes need no network. Does nothing when the bundle is
# newer than its inputs. Without npm it says so and exits 0: the viewer commands then say how to
# install it, and the browser tests skip naming npm as the reason.
#   scripts/web_viewer.sh        -> prints the viewer folder (AVSPLAT_WEB_VIEWER takes it)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
packages=(@sparkjsdev/spark@2.2.0 three@0.180.0 esbuild@0.25.12 playwright-core@1.56.1)
dir="$root/build-node/viewer"
dist="$dir/dist"
stamp="$dir/installed-packages"
if ! command -v npm >/dev/null 2>&1; then
  echo "npm not found: the web viewer (Spark 2.2.0) is not installed; avsplat view/convert to .html and the browser tests need it" >&2
  exit 0
fi
mkdir -p "$dir"
if [ "$(cat "$stamp" 2>/dev/null)" != "${packages[*]}" ]; then
  npm install --prefix "$dir" --no-audit --no-fund --loglevel=error --save-exact "${packages[@]}" >&2
  echo "${packages[*]}" > "$stamp"
  rm -rf "$dist"
fi
bundle="$dist/avsplat-viewer.js"
if [ ! -f "$bundle" ] || [ "$root/web/viewer.js" -nt "$bundle" ] || [ "$root/web/viewer.html" -nt "$bundle" ] \
   || [ "$stamp" -nt "$bundle" ]; then
  mkdir -p "$dist"
  # The entry imports three and Spark by name; they resolve in build-node/viewer/node_modules.
  cp "$root/web/viewer.js" "$dir/viewer-entry.js"
  "$dir/node_modules/.bin/esbuild" "$dir/viewer-entry.js" --bundle --format=esm --minify \
    --legal-comments=inline --log-level=warning --outfile="$bundle.tmp"
  cp "$root/web/viewer.html" "$dist/viewer.html"
  mv "$bundle.tmp" "$bundle"
fi
echo "$dist"
