#!/usr/bin/env bash
# The test command: sets up, builds, then runs every test (ctest for C++ and the install
# consumer, `pip install .` into a fresh venv, pytest for Python, the notebooks and the documentation's examples), checks that the
# tree speaks of the product only, and builds the documentation with warnings as errors. Exits
# non-zero on any failure, including pytest collecting no tests (exit code 5).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/setup.sh" "$@"

echo "== Words of the tree =="
bash "$root/scripts/check_words.sh"

echo "== Documentation (Sphinx, warnings as errors) =="
bash "$root/scripts/docs.sh"

echo "== C++ tests (ctest) =="
ctest --test-dir "$root/build" --output-on-failure -j"$(nproc)"

echo "== PlayCanvas splat-transform (the peer some Python tests compare with) =="
bash "$root/scripts/splat_transform.sh" >/dev/null

echo "== The web viewer (Spark from npm, for avsplat view / .html and the browser tests) =="
bash "$root/scripts/web_viewer.sh" >/dev/null

echo "== Python stubs and types (stubgen, mypy) =="
bash "$root/scripts/stubs.sh" --check

echo "== pip install . into a fresh venv (README example, avsplat --version) =="
bash "$root/scripts/pip_check.sh"

echo "== Python tests and notebooks (pytest) =="
cd "$root"
PYTHONPATH="$root/build/python" /usr/bin/python3 -m pytest -q tests/python
