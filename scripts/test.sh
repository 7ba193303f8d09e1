#!/usr/bin/env bash
# Set-up, build and the whole test suite: the release build, then (unless TEACHSIM_SKIP_ASAN=1)
# the address + undefined sanitizer build. This is the README's test command and what CI runs.
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
