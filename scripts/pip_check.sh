#!/usr/bin/env bash
# `pip install .` as a user does it: a fresh venv (with Debian's numpy and Open3D through
# --system-site-packages), the checkout installed offline, then, from a folder outside the source
# tree, the README's Python example and the console command. Reuses ccache, and the CMake folder
# build-pip-<python tag>/ when it exists, so a second run takes a minute, not a cold build.
#   scripts/pip_check.sh [python]   (default /usr/bin/python3)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
python="${1:-/usr/bin/python3}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

"$python" -m venv --system-site-packages "$work/venv"
"$work/venv/bin/python" -m pip install --quiet --no-build-isolation --no-index "$root"

cd "$work"
# The README's first python block, run as written by the venv's interpreter.
"$work/venv/bin/python" - "$root/README.md" > example.py <<'PY'
import re, sys
text = open(sys.argv[1]).read()
blocks = re.findall(r"^```python\n(.*?)^```", text, re.M | re.S)
if not blocks:
    sys.exit("README.md has no python block")
print(blocks[0])
PY
"$work/venv/bin/python" example.py
test -s fused.ply || { echo "pip check: the README example wrote no fused.ply" >&2; exit 1; }

# The package and the tool come from the venv, not from the source or build tree.
"$work/venv/bin/python" - "$root" <<'PY'
import pathlib, sys
import avsplat
where = pathlib.Path(avsplat.__file__).resolve()
root = pathlib.Path(sys.argv[1]).resolve()
assert root not in where.parents, f"avsplat imported from the source tree: {where}"
assert (where.parent / "py.typed").is_file() and (where.parent / "_avsplat.pyi").is_file(), "py.typed or the stubs are missing"
print("avsplat", avsplat.__version__, "from", where.parent)
PY
version="$("$work/venv/bin/avsplat" --version)"
expected="$("$work/venv/bin/python" -c 'import avsplat; print(avsplat.__version__)')"
case "$version" in
  *"$expected"*) echo "avsplat --version: $version" ;;
  *) echo "pip check: avsplat --version printed '$version', the package is $expected" >&2; exit 1 ;;
esac
# `avsplat eval` finds the installed package through the console script.
eval_output="$("$work/venv/bin/avsplat" eval no_such_report 2>&1 || true)"
case "$eval_output" in
  *"unknown report 'no_such_report'"*) ;;
  *) echo "pip check: avsplat eval did not reach the installed package: $eval_output" >&2; exit 1 ;;
esac
echo "pip check: passed"
