#!/usr/bin/env bash
# Coverage-guided fuzzing of every reader: builds the libFuzzer harnesses of tests/fuzz with
# clang under AddressSanitizer and UndefinedBehaviorSanitizer into build-fuzz/, then runs each
# from its seed corpus (tests/fuzz/corpus/<reader>) for a fixed number of inputs with a fixed seed
# (the fast readers reach the count, so their run is reproducible; the slow ones stop at a time
# limit, below), so that CI's verdict depends as little as possible on luck. Any finding (crash,
# sanitizer report, an input slower than 10 s, an allocation over 1 GiB, an exception other than
# the documented IOError / invalid_argument) fails the run and leaves the input in
# build-fuzz/findings/. New inputs that raise coverage go to build-fuzz/corpus/, never to the
# repository's seed folders.
#   scripts/fuzz.sh [inputs per reader, default 150000] [seed, default 1] [seconds per reader, default 45]
# A reader stops at whichever comes first, its inputs or its seconds, so that the whole step stays
# under 10 minutes with a dozen readers (the slow ones, SOG's WebP and SPZ's inflate, reach the
# time before the count).
# Longer exploratory runs: scripts/fuzz.sh 10000000 $RANDOM (keep build-fuzz/corpus between runs).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
runs="${1:-150000}"
seed="${2:-1}"
seconds="${3:-45}"
source "$root/scripts/packages.sh"
ensure_packages clang-14 libfuzzer-14-dev libclang-rt-14-dev libomp-14-dev cmake ccache \
  libeigen3-dev libnanoflann-dev nlohmann-json3-dev zlib1g-dev libpng-dev libzip-dev libzstd-dev libwebp-dev \
  pkg-config
build="$root/build-fuzz"
san="-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer -g -O1"
cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER=clang-14 -DCMAKE_CXX_COMPILER=clang++-14 \
  -DAVSPLAT_WITH_OPEN3D=OFF -DAVSPLAT_WITH_PYTHON=OFF -DAVSPLAT_WITH_CUDA=OFF \
  -DAVSPLAT_BUILD_APPS=OFF -DAVSPLAT_BUILD_BENCHMARKS=OFF -DAVSPLAT_BUILD_TESTS=OFF \
  -DAVSPLAT_BUILD_FUZZERS=ON \
  -DCMAKE_CXX_FLAGS="$san -fsanitize=fuzzer-no-link" \
  -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" >/dev/null
cmake --build "$build" -j"$(nproc)"
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
# One thread: coverage from OpenMP workers would make the corpus, and so the run, vary.
export OMP_NUM_THREADS=1
mkdir -p "$build/findings"
status=0
for harness in "$build"/tests/fuzz/fuzz_*; do
  reader="${harness##*/fuzz_}"
  corpus="$build/corpus/$reader"
  mkdir -p "$corpus"
  echo "== fuzz $reader ($runs inputs, seed $seed) =="
  if ! "$harness" "$corpus" "$root/tests/fuzz/corpus/$reader" -runs="$runs" -seed="$seed" -max_total_time="$seconds" \
       -timeout=10 -malloc_limit_mb=1024 -rss_limit_mb=2048 -max_len=65536 \
       -artifact_prefix="$build/findings/$reader-" -print_final_stats=1 2>"$build/$reader.log"; then
    echo "fuzz $reader: FINDING (see $build/$reader.log and $build/findings/)"
    tail -n 40 "$build/$reader.log"
    status=1
  else
    grep -E '^stat::number_of_executed_units|^stat::new_units_added' "$build/$reader.log" | tr '\n' ' '
    echo
  fi
done
exit $status
