#!/usr/bin/env bash
# Configures and builds one configuration. Usage: scripts/build.sh [release|asan]
set -euo pipefail
cd "$(dirname "$0")/.."
config=${1:-release}
case "$config" in
  release) dir=build; flags=(-DCMAKE_BUILD_TYPE=Release) ;;
  # The sanitizer build is for the tests: -O1 with line tables only (half the compile time of -O2 -g,
  # and the sanitizers' reports still name file and line), no benchmarks.
  asan) dir=build-asan
    flags=(-DCMAKE_BUILD_TYPE=RelWithDebInfo "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG"
           -DTEACHSIM_SANITIZE=ON -DTEACHSIM_BUILD_BENCHMARKS=OFF) ;;
  *) echo "build: unknown configuration '$config' (release or asan)" >&2; exit 2 ;;
esac
jobs=${TEACHSIM_JOBS:-$(nproc)}
cmake -S . -B "$dir" -G Ninja "${flags[@]}" > "$dir.configure.log" 2>&1 || { cat "$dir.configure.log"; exit 1; }
cmake --build "$dir" -j "$jobs"
