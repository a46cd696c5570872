#!/usr/bin/env bash
# scripts/gpu_check.sh on a CUDA machine that lacks the core's -dev packages (a CUDA container
# image: nvcc, CMake and Python with numpy, pytest and pybind11, but no Eigen, nlohmann-json,
# nanoflann, Catch2, libzip, libwebp, libpng or zstd headers). Two steps:
#
#   bash scripts/gpu_deps.sh fetch DIR           # here, on Debian 12: apt-get download the packages into DIR
#   bash scripts/gpu_deps.sh run DIR [RESULTS]   # there: unpack them into a private prefix, run gpu_check.sh
#
# `run` unpacks every DIR/*.deb into $DEPS_ROOT (default /opt/avsplat-deps; nothing is written
# outside it), re-points the packages' absolute links into it, exports CMAKE_PREFIX_PATH,
# PKG_CONFIG_PATH / PKG_CONFIG_SYSROOT_DIR and LD_LIBRARY_PATH to it (and pybind11's CMake
# directory when Python has pybind11), and builds in its own folder (build-gpu-deps) with
# /usr/bin/g++ when that exists, even where the image sets CXX ($GPU_DEPS_CXX chooses another):
# on the one CUDA image measured, its CXX (/opt/gcc/bin/g++, a wrapper) linked libstdc++
# statically into the Python module, which then crashed on import after numpy (two copies of
# libstdc++'s locale). The packages are Debian 12's (glibc 2.36), so the machine needs glibc 2.36
# or newer.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$root/scripts/packages.sh"
# The core's -dev packages (packages.sh), the shared libraries they link at run time, and
# pkg-config's own (pkg-config itself is a transitional package in Debian 12).
PACKAGES="${core_dev_packages[*]} libzstd1 libzip4 libwebp7 libwebpdemux2 libwebpmux3 libpng16-16 zlib1g
libbz2-1.0 liblzma5 libssl3 pkgconf pkgconf-bin libpkgconf3"

case "${1:-}" in
fetch)
    dir="${2:?usage: gpu_deps.sh fetch DIR}"
    mkdir -p "$dir"
    # shellcheck disable=SC2086
    (cd "$dir" && apt-get download $PACKAGES)
    ls "$dir"/*.deb | wc -l | xargs echo "packages in $dir:"
    ;;
run)
    dir="${2:?usage: gpu_deps.sh run DIR [RESULTS_DIR]}"
    shift 2
    d="${DEPS_ROOT:-/opt/avsplat-deps}"
    mkdir -p "$d"
    for f in "$dir"/*.deb; do dpkg -x "$f" "$d"; done
    find "$d" -type l -lname '/*' | while read -r l; do ln -sfn "$d$(readlink "$l")" "$l"; done
    pyb="$(python3 -c 'import os, pybind11; print(os.path.dirname(pybind11.__file__))' 2>/dev/null || true)"
    export CMAKE_PREFIX_PATH="$d/usr:$d${pyb:+:$pyb}${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
    export PKG_CONFIG_PATH="$d/usr/lib/x86_64-linux-gnu/pkgconfig:$d/usr/share/pkgconfig"
    export PKG_CONFIG_SYSROOT_DIR="$d"
    export PATH="$PATH:$d/usr/bin"
    export LD_LIBRARY_PATH="$d/usr/lib/x86_64-linux-gnu:$d/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
    export PYTHON="${PYTHON:-python3}"
    # A build folder of its own: CMake keeps the compiler a folder was configured with.
    export BUILD_DIR="${BUILD_DIR:-$root/build-gpu-deps}"
    # The system compiler, even where the image sets CXX (GPU_DEPS_CXX chooses another).
    cxx="${GPU_DEPS_CXX:-/usr/bin/g++}"
    if [ -x "$cxx" ]; then export CXX="$cxx" CUDAHOSTCXX="$cxx"; fi  # (the project uses no C compiler)
    echo "gpu_deps: prefix $d, C++ ${CXX:-default}, python $(command -v "$PYTHON"), pybind11 ${pyb:-not found}"
    exec bash "$root/scripts/gpu_check.sh" "$@"
    ;;
*)
    sed -n '2,17p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
    exit 2
    ;;
esac
