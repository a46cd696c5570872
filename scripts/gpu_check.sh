#!/usr/bin/env bash
# The GPU check of the CUDA renderer, one command on a machine with an NVIDIA GPU:
#
#   bash scripts/gpu_check.sh [RESULTS_DIR]
#
# 1. configures a build with CUDA (AVSPLAT_WITH_CUDA=ON; Open3D off, it is not needed here;
#    Python on when pybind11, numpy and pytest are importable) and builds the CUDA tests, the
#    CUDA benchmark and, with Python, the module;
# 2. runs the CUDA renderer's C++ tests: the [gpu] cases (ctest -L gpu) and the host-side ones;
# 3. runs tests/python/test_render_cuda.py when Python is on;
# 4. runs bench_render_cuda (bench_render's scene: 500,000 Gaussians of SH degree 3, 1280 x 720,
#    5 views; BENCH_ARGS to change it).
# Everything goes to RESULTS_DIR (default: $OUT if set, else BUILD_DIR/gpu_check_results): device.txt,
# build.log, ctest_gpu.txt, tests_render_cuda.txt, pytest_render_cuda.txt, bench_render_cuda.txt
# and summary.txt. Exits non-zero when the build or a test fails, or when no GPU is usable (a
# skipped GPU test is a failure here: this script exists to run them).
#
# Environment: BUILD_DIR (default build-gpu), CUDA_ARCHS (default: the GPU's own, "native", with
# CMake >= 3.24; "75;80;86;89;90" builds the release set), JOBS (default nproc), BENCH_ARGS.
# Needs what the core needs (CMake, a C++17 compiler with OpenMP, Eigen, nlohmann-json,
# nanoflann, Catch2 v2) and the CUDA toolkit; not Open3D (the apps are not built).
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${BUILD_DIR:-$root/build-gpu}"
results="${1:-${OUT:-$build/gpu_check_results}}"
# "native" (the GPU's own architecture) needs CMake 3.24; older CMake builds the release set.
if cmake -P /dev/stdin <<<'if(CMAKE_VERSION VERSION_LESS 3.24)
message(FATAL_ERROR "old")
endif()' >/dev/null 2>&1; then default_archs=native; else default_archs="75;80;86;89;90"; fi
archs="${CUDA_ARCHS:-$default_archs}"
jobs="${JOBS:-$(nproc)}"
mkdir -p "$results"
summary="$results/summary.txt"
: >"$summary"
status=0
note() { echo "$*" | tee -a "$summary"; }

{
    echo "date: $(date -u +%FT%TZ)"
    echo "commit: $(git -C "$root" rev-parse HEAD 2>/dev/null || echo unknown)"
    nvidia-smi 2>&1 || echo "nvidia-smi not available"
    nvcc_bin="$(command -v nvcc || echo /usr/local/cuda/bin/nvcc)"
    "$nvcc_bin" --version 2>&1 || echo "nvcc not found"
} >"$results/device.txt"

# The first of $PYTHON, /usr/bin/python3 and python3 that has numpy, pytest and pybind11.
with_python=OFF
python_bin=python3
for candidate in ${PYTHON:-} /usr/bin/python3 python3; do
    if "$candidate" -c "import numpy, pytest, pybind11" >/dev/null 2>&1; then
        python_bin="$candidate"
        with_python=ON
        break
    fi
done
note "gpu_check: build $build, CUDA architectures $archs, Python $with_python ($python_bin)"

{
    cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=Release -DAVSPLAT_WITH_CUDA=ON \
        -DCMAKE_CUDA_ARCHITECTURES="$archs" -DAVSPLAT_WITH_OPEN3D=OFF -DAVSPLAT_BUILD_APPS=OFF \
        -DAVSPLAT_WITH_PYTHON=$with_python -DPython_EXECUTABLE="$python_bin" -DPYBIND11_FINDPYTHON=ON &&
        cmake --build "$build" -j"$jobs" --target avsplat_render_cuda_tests bench_render_cuda &&
        if [ "$with_python" = ON ]; then cmake --build "$build" -j"$jobs" --target _avsplat; fi
} >"$results/build.log" 2>&1
if [ $? -ne 0 ]; then
    note "FAILED: build (see build.log)"
    tail -30 "$results/build.log"
    exit 1
fi
note "build: ok"

ctest --test-dir "$build" -L gpu --output-on-failure -V >"$results/ctest_gpu.txt" 2>&1
rc=$?
if grep -q "SKIPPED: no CUDA device" "$results/ctest_gpu.txt"; then
    note "FAILED: ctest -L gpu skipped the GPU tests: no CUDA device (see ctest_gpu.txt)"
    status=1
elif [ $rc -ne 0 ]; then
    note "FAILED: ctest -L gpu (rc $rc; see ctest_gpu.txt)"
    status=1
else
    note "ctest -L gpu: $(grep -E 'tests passed|tests failed' "$results/ctest_gpu.txt" | tail -1)"
fi

"$build/tests/avsplat_render_cuda_tests" --durations yes >"$results/tests_render_cuda.txt" 2>&1
rc=$?
if [ $rc -ne 0 ]; then note "FAILED: avsplat_render_cuda_tests (rc $rc)"; status=1; fi
note "avsplat_render_cuda_tests: $(grep -E '^(All tests passed|test cases:)' "$results/tests_render_cuda.txt" | tail -1)"

if [ "$with_python" = ON ]; then
    (cd "$root" && PYTHONPATH="$build/python" "$python_bin" -m pytest -v -rs tests/python/test_render_cuda.py) \
        >"$results/pytest_render_cuda.txt" 2>&1
    rc=$?
    # One test is skipped by design when a device is present (it checks the no-device error).
    if [ $rc -ne 0 ] || grep -qE "SKIPPED: (no CUDA device|render: avsplat was built without)" \
        "$results/pytest_render_cuda.txt"; then
        note "FAILED or skipped: pytest test_render_cuda.py (rc $rc)"
        status=1
    fi
    note "pytest: $(tail -1 "$results/pytest_render_cuda.txt")"
fi

# shellcheck disable=SC2086
"$build/apps/benchmarks/bench_render_cuda" ${BENCH_ARGS:-} >"$results/bench_render_cuda.txt" 2>&1
rc=$?
if [ $rc -ne 0 ]; then note "FAILED: bench_render_cuda (rc $rc)"; status=1; fi
grep -E "^(bench_render_cuda|GPU:|all views|CUDA is)" "$results/bench_render_cuda.txt" | tee -a "$summary"

note "gpu_check: $([ $status -eq 0 ] && echo PASSED || echo FAILED); results in $results"
exit $status
