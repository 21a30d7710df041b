#!/usr/bin/env bash
# Builds the fuzz targets of tests/fuzz with clang's libFuzzer, AddressSanitizer and
# UndefinedBehaviorSanitizer (in build-fuzz, or STEVI_FUZZ_BUILD_DIR), and runs each for a while.
#
# Usage: bash deploy/fuzz.sh [--seconds N] [--merge] [TARGET ...]
#   --seconds N  how long each target runs (default 600)
#   --merge      afterwards, minimise each target's corpus (tests/fuzz/corpus/TARGET plus what the
#                run found) back into tests/fuzz/corpus/TARGET, keeping the regression-* inputs
#   TARGET       mavlink, flags, ... (default: every tests/fuzz/*_fuzz.cc)
# Each run's output is in BUILD/fuzz-TARGET.log; its last lines are libFuzzer's final statistics
# (executions, coverage). A crash leaves crash-* in BUILD/findings/TARGET and fails the script.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=600
merge=0
targets=()
while (($#)); do
  case "$1" in
    --seconds) seconds="$2"; shift 2 ;;
    --merge) merge=1; shift ;;
    -*) echo "fuzz.sh: unknown option $1" >&2; exit 2 ;;
    *) targets+=("$1"); shift ;;
  esac
done
if ((${#targets[@]} == 0)); then
  for f in tests/fuzz/*_fuzz.cc; do targets+=("$(basename "$f" _fuzz.cc)"); done
fi
build_dir="${STEVI_FUZZ_BUILD_DIR:-build-fuzz}"
CXX=clang++ cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSTEVI_BUILD_TESTS=ON \
  -DSTEVI_BUILD_BENCHMARKS=OFF -DSTEVI_FUZZ=ON -DSTEVI_SANITIZE=address,undefined >/dev/null
cmake --build "$build_dir" -j"$(nproc)" --target "${targets[@]/#/fuzz_}"

export ASAN_OPTIONS="detect_leaks=1"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1"
failed=0
for t in "${targets[@]}"; do
  work="$build_dir/corpus/$t" findings="$build_dir/findings/$t"
  mkdir -p "$work" "$findings"
  echo "fuzz.sh: $t for $seconds s"
  if ! "$build_dir/bin/fuzz_$t" -max_total_time="$seconds" -print_final_stats=1 \
      -rss_limit_mb=4096 -artifact_prefix="$findings/" "$work" "tests/fuzz/corpus/$t" \
      >"$build_dir/fuzz-$t.log" 2>&1; then
    echo "fuzz.sh: $t FOUND A CRASH: $(ls "$findings")" >&2
    failed=1
  fi
  grep -E "^stat::number_of_executed_units|^#[0-9]+.*DONE" "$build_dir/fuzz-$t.log" || true
  if ((merge)); then
    fresh="$build_dir/merged/$t"
    rm -rf "$fresh" && mkdir -p "$fresh"
    "$build_dir/bin/fuzz_$t" -merge=1 "$fresh" "tests/fuzz/corpus/$t" "$work" \
      >"$build_dir/merge-$t.log" 2>&1
    find "tests/fuzz/corpus/$t" -type f ! -name 'regression-*' -delete
    cp "$fresh"/* "tests/fuzz/corpus/$t/"
    echo "fuzz.sh: $t corpus now $(ls "tests/fuzz/corpus/$t" | wc -l) files"
  fi
done
exit "$failed"
