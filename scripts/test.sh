#!/usr/bin/env bash
# Set-up, build and the whole test suite. This is the README's test command and what CI runs.
#
# Stages, in order:
#   1. set-up (scripts/setup.sh), the release build and its ctest run: always.
#   2. the address + undefined sanitizer build and its ctest run (skip: TEACHSIM_SKIP_ASAN=1).
#   3. the libFuzzer harnesses, built with clang, each run for TEACHSIM_FUZZ_SECONDS (default 30;
#      skip: TEACHSIM_SKIP_FUZZ=1; fuzz/README.md).
#
# Time budget: CI stops a run after 90 minutes. Stages 2 and 3 run only while they fit in
# TEACHSIM_TEST_BUDGET_MIN minutes from the start (default 80; 0: no budget). A stage that would not
# fit is skipped, and one that reaches the budget is stopped; either is reported in the summary
# below, and neither fails the run. A failing build or test always fails it.
set -euo pipefail
cd "$(dirname "$0")/.."

budget_s=$((${TEACHSIM_TEST_BUDGET_MIN:-80} * 60))
fuzz_reserve_s=600  # the fuzzing stage from a cold start on 2 cores: ~8 minutes
summary=()
stage_start=0

begin() { stage_start=$SECONDS; echo "test: --- $1 (at $((SECONDS / 60)) min $((SECONDS % 60)) s)"; }
finish() { summary+=("$1: $2 in $((SECONDS - stage_start)) s"); }
# Seconds left before the budget, less what must stay for later stages ($1); a large number
# without a budget.
left() { if ((budget_s > 0)); then echo $((budget_s - SECONDS - ${1:-0})); else echo 999999; fi; }
report() {
  echo "test: ===== summary (${SECONDS} s in all; budget ${TEACHSIM_TEST_BUDGET_MIN:-80} min)"
  local line
  for line in "${summary[@]}"; do echo "test:   $line"; done
}
trap report EXIT

begin "set-up"
bash scripts/setup.sh
finish "set-up" "done"

begin "release build"
bash scripts/build.sh release
finish "release build" "done"

begin "release tests"
(cd build && ctest --output-on-failure --timeout 600 -j "$(nproc)")
finish "release tests" "passed"

# Runs "$@" with at most $1 seconds; returns 124 when stopped at that limit.
run_within() {
  local limit=$1
  shift
  ((limit > 0)) || return 124
  timeout --kill-after=30 "$limit" "$@"
}

# Ends stage $1 by its status $2: 0 done ($3), 124 stopped at the budget ($4), else failed (exits).
conclude() {
  if (($2 == 0)); then
    finish "$1" "$3"
  elif (($2 == 124)); then
    finish "$1" "STOPPED at the time budget ($4)"
  else
    finish "$1" "FAILED"
    exit "$2"
  fi
}

# ctest "$@" in the current folder with at most $1 seconds, its output also in ctest-run.log. When
# stopped at the limit, 124 only if none of the tests that had finished failed (else 1).
ctest_within() {
  local limit=$1 status=0
  shift
  run_within "$limit" ctest "$@" 2>&1 | tee ctest-run.log || status=${PIPESTATUS[0]}
  if ((status == 124)) && grep -qE '\*\*\*(Failed|Exception|Timeout)|\(Failed\)' ctest-run.log; then
    echo "test: tests had failed before the time budget stopped the run (ctest-run.log)"
    status=1
  fi
  return "$status"
}

if [[ "${TEACHSIM_SKIP_ASAN:-0}" == 1 ]]; then
  summary+=("sanitizer build and tests: skipped (TEACHSIM_SKIP_ASAN=1)")
else
  reserve=0
  [[ "${TEACHSIM_SKIP_FUZZ:-0}" == 1 ]] || reserve=$fuzz_reserve_s
  # Started while at least 10 minutes remain before the budget less the fuzzing stage's reserve,
  # and stopped at that point.
  limit=$(left "$reserve")
  if ((limit < 600)); then
    summary+=("sanitizer build and tests: skipped, ${limit} s left in the budget (10 minutes at least)")
  else
    begin "sanitizer build"
    status=0
    run_within "$limit" bash scripts/build.sh asan || status=$?
    conclude "sanitizer build" "$status" "done" "not finished; its tests did not run"
    if ((status == 0)); then
      begin "sanitizer tests"
      (cd build-asan && export ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
         TEACHSIM_SANITIZER_BUILD=1 &&
         ctest_within "$(left "$reserve")" --output-on-failure --timeout 900 -j "$(nproc)" -LE slow) \
        || status=$?
      conclude "sanitizer tests" "$status" "passed" "those that had finished passed"
    fi
  fi
fi

if [[ "${TEACHSIM_SKIP_FUZZ:-0}" == 1 ]]; then
  summary+=("fuzzing: skipped (TEACHSIM_SKIP_FUZZ=1)")
elif (($(left) < fuzz_reserve_s)); then
  summary+=("fuzzing: skipped, $(left) s left in the budget and about ${fuzz_reserve_s} s needed")
else
  # Only the harnesses are built here (the module libraries are compiled again, instrumented, in
  # fuzz/); 30 s per harness keeps the stage under ~8 minutes on 2 cores from a cold start.
  begin "fuzzing"
  cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=Release -DTEACHSIM_FUZZ=ON \
    -DCMAKE_CXX_COMPILER=clang++ -DTEACHSIM_BUILD_BENCHMARKS=OFF \
    -DTEACHSIM_FUZZ_SECONDS="${TEACHSIM_FUZZ_SECONDS:-30}" > build-fuzz.configure.log 2>&1 \
    || { cat build-fuzz.configure.log; exit 1; }
  status=0
  run_within "$(left)" cmake --build build-fuzz --target teachsim_fuzzers -j "${TEACHSIM_JOBS:-$(nproc)}" \
    || status=$?
  if ((status == 0)); then
    (cd build-fuzz && ctest_within "$(left)" -L fuzz --output-on-failure -j "$(nproc)") || status=$?
  fi
  conclude "fuzzing" "$status" "passed" "those that had finished passed"
fi
