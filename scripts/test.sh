#!/usr/bin/env bash
# Set-up, build and the whole test suite: the release build, then (unless TEACHSIM_SKIP_ASAN=1)
# the address + undefined sanitizer build, then (unless TEACHSIM_SKIP_FUZZ=1) the libFuzzer
# harnesses, built with clang and each run for TEACHSIM_FUZZ_SECONDS (fuzz/README.md).
# This is the README's test command and what CI runs.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh release
(cd build && ctest --output-on-failure --timeout 600 -j "$(nproc)")
if [[ "${TEACHSIM_SKIP_ASAN:-0}" != 1 ]]; then
  bash scripts/build.sh asan
  (cd build-asan && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
     TEACHSIM_SANITIZER_BUILD=1 ctest --output-on-failure --timeout 900 -j "$(nproc)" -LE slow)
fi
if [[ "${TEACHSIM_SKIP_FUZZ:-0}" != 1 ]]; then
  # Only the harnesses are built here (the module libraries are compiled again, instrumented, in
  # fuzz/); 30 s per harness keeps the stage under ~8 minutes on 2 cores from a cold ccache.
  cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=Release -DTEACHSIM_FUZZ=ON \
    -DCMAKE_CXX_COMPILER=clang++ -DTEACHSIM_BUILD_BENCHMARKS=OFF \
    -DTEACHSIM_FUZZ_SECONDS="${TEACHSIM_FUZZ_SECONDS:-30}" > build-fuzz.configure.log 2>&1 \
    || { cat build-fuzz.configure.log; exit 1; }
  cmake --build build-fuzz --target teachsim_fuzzers -j "${TEACHSIM_JOBS:-$(nproc)}"
  (cd build-fuzz && ctest -L fuzz --output-on-failure -j "$(nproc)")
fi
