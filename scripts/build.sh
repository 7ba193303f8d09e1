#!/usr/bin/env bash
# Configures and builds one configuration. Usage: scripts/build.sh [release|asan]
set -euo pipefail
cd "$(dirname "$0")/.."
config=${1:-release}
case "$config" in
  release) dir=build; flags=(-DCMAKE_BUILD_TYPE=Release) ;;
  asan) dir=build-asan; flags=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DTEACHSIM_SANITIZE=ON) ;;
  *) echo "build: unknown configuration '$config' (release or asan)" >&2; exit 2 ;;
esac
jobs=${TEACHSIM_JOBS:-$(nproc)}
cmake -S . -B "$dir" -G Ninja "${flags[@]}" > "$dir.configure.log" 2>&1 || { cat "$dir.configure.log"; exit 1; }
cmake --build "$dir" -j "$jobs"
