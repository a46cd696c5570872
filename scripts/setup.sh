#!/usr/bin/env bash
# Installs what avsplat needs from Debian 12 (only what is missing), then configures and builds
# into build/ at the repository root. Used by the README's two commands; safe to re-run.
#   scripts/setup.sh [extra cmake -D options...]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

source "$root/scripts/packages.sh"
packages=(
  build-essential cmake ccache git "${core_dev_packages[@]}"
  libopen3d-dev python3-open3d libcli11-dev
  pybind11-dev python3-pybind11 python3-dev
  python3-setuptools python3-wheel python3-pip python3-venv  # pip install . (setup.py, scripts/pip_check.sh)
  python3-numpy python3-pytest python3-matplotlib python3-nbclient python3-ipykernel
  python3-nbformat python3-dask python3-distributed python3-hypothesis
  python3-sphinx python3-myst-parser python3-numpydoc python3-breathe doxygen python3-nbsphinx  # scripts/docs.sh
  linux-perf  # the profiles of docs/benchmarks/fusion.md (perf record -e cpu-clock)
  chromium  # the web viewer's browser tests (headless; scripts/web_viewer.sh installs the viewer)
)
ensure_packages "${packages[@]}"

# CUDA is optional: the toolkit is used when nvcc is found (AVSPLAT_WITH_CUDA=AUTO).
cmake -S "$root" -B "$root/build" -DCMAKE_BUILD_TYPE=Release \
  -DPython_EXECUTABLE=/usr/bin/python3 -DPYBIND11_FINDPYTHON=ON "$@" >/dev/null
cmake --build "$root/build" -j"$(nproc)"
