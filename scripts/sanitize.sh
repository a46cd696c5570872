#!/usr/bin/env bash
# Builds the core and its C++ tests under AddressSanitizer and UndefinedBehaviorSanitizer in
# build-sanitize/ and runs them; any sanitizer report fails the run. Open3D, Python and CUDA
# are left out: the point is our code, not the system libraries'.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
flags="-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer -g -O1"
cmake -S "$root" -B "$root/build-sanitize" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DAVSPLAT_WITH_OPEN3D=OFF -DAVSPLAT_WITH_PYTHON=OFF -DAVSPLAT_WITH_CUDA=OFF \
  -DAVSPLAT_BUILD_APPS=OFF -DAVSPLAT_BUILD_BENCHMARKS=OFF \
  -DCMAKE_CXX_FLAGS="$flags" -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" >/dev/null
cmake --build "$root/build-sanitize" -j"$(nproc)" --target avsplat_tests avsplat_prune_tests
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:strict_string_checks=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
echo "== C++ tests under ASan + UBSan =="
ctest --test-dir "$root/build-sanitize" --output-on-failure -j"$(nproc)" -L cpp
