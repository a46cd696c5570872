#!/usr/bin/env bash
# Builds the documentation site into build/docs/html with Sphinx from Debian's packages, warnings
# as errors. Needs the build (build/apps/avsplat, build/python): the CLI reference is the tool's
# own --help, the Python reference its docstrings, the C++ reference the public headers (doxygen).
#   scripts/docs.sh            after scripts/setup.sh
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$root/build/docs"
python=/usr/bin/python3   # Debian's: Sphinx, numpy and the extensions live there

[ -x "$root/build/apps/avsplat" ] || { echo "docs.sh: build/apps/avsplat is missing; run scripts/setup.sh" >&2; exit 1; }

# The Python package in build/python is copied from bindings/avsplat by the build; refresh it.
cmake --build "$root/build" --target avsplat_python >/dev/null

# The Sphinx source is docs/ plus the generated pages, assembled in build/docs/src.
rm -rf "$out/src" "$out/doxygen" "$out/doctrees"
mkdir -p "$out/src" "$out/doxygen"
cp -r "$root/docs/." "$out/src/"
PYTHONPATH="$root/build/python" "$python" "$root/scripts/docs_generate.py" "$root" "$out/src"

# C++: doxygen XML of the public headers, read by breathe.
( cd "$root" && sed -e "s|@OUT@|$out/doxygen|" "$root/docs/Doxyfile.in" | doxygen - >"$out/doxygen.log" 2>&1 ) \
  || { cat "$out/doxygen.log" >&2; exit 1; }

PYTHONPATH="$root/build/python" AVSPLAT_DOXYGEN_XML="$out/doxygen/xml" \
  "$python" -m sphinx -W --keep-going -q -b html -d "$out/doctrees" "$out/src" "$out/html"
echo "docs: $out/html/index.html"
