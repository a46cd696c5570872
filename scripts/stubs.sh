#!/usr/bin/env bash
# Type stubs of the compiled module: regenerates bindings/avsplat/_avsplat.pyi from the built
# module with mypy's stubgen, then checks the package with mypy (mypy.ini). With --check (what
# the test command runs) the committed stubs must equal freshly generated ones, so a binding
# whose signature changed without its stubs fails CI.
#   scripts/stubs.sh [--check]     (after the build: needs build/python)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
python=/usr/bin/python3
committed="$root/bindings/avsplat/_avsplat.pyi"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

PYTHONPATH="$root/build/python" "$python" -c "import sys; from mypy.stubgen import main; sys.argv[0] = 'stubgen'; main()" -q -m avsplat._avsplat -o "$work"
PYTHONPATH="$root/build/python" "$python" "$root/scripts/stubs_tidy.py" "$work/avsplat/_avsplat.pyi"
if [ "${1:-}" = "--check" ]; then
  if ! diff -u "$committed" "$work/avsplat/_avsplat.pyi" > "$work/diff"; then
    head -40 "$work/diff"
    echo "bindings/avsplat/_avsplat.pyi is stale: run scripts/stubs.sh and commit it" >&2
    exit 1
  fi
else
  cp "$work/avsplat/_avsplat.pyi" "$committed"
fi
cd "$root"
"$python" -m mypy --config-file mypy.ini bindings/avsplat tests/python/test_typed_api.py
