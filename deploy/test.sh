#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine, checks the code (format, function size), builds stevi with its
# tests and benchmarks, and runs every test; then builds the tests again under AddressSanitizer
# with UndefinedBehaviorSanitizer and runs them all again (deploy/sanitize.sh address, in
# build-asan; STEVI_SANITIZE_BUILD_DIR picks another folder).
# Usage: bash deploy/test.sh        (STEVI_BUILD_DIR picks the build folder; default ./build)
# The reference data is read from $STEVI_DATA_DIR (default ../shared/data); tests that need it
# skip with a message when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir="${STEVI_BUILD_DIR:-build}"
jobs="$(nproc)"

# Each stage says how long it took, so that a slow CI run shows where its time went.
stage() {
  local name="$1" start
  shift
  start=$(date +%s)
  "$@"
  echo "test.sh: $name took $(( $(date +%s) - start )) s"
}

stage "install-deps" bash deploy/install-deps.sh
stage "format check" bash deploy/check-code.sh --format-only
stage "configure" cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DSTEVI_BUILD_TESTS=ON -DSTEVI_BUILD_BENCHMARKS=ON -DSTEVI_WERROR=ON \
  -DCMAKE_EXPORT_COMPILE_COMMANDS=ON
stage "build" cmake --build "$build_dir" -j"$jobs"
stage "code checks" bash deploy/check-code.sh "$build_dir"
stage "tests" ctest --test-dir "$build_dir" --output-on-failure -j"$jobs"
stage "sanitized build and tests" bash deploy/sanitize.sh address
