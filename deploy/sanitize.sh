#!/usr/bin/env bash
# Builds the tests with sanitizers, in a folder of their own, and runs them. A sanitizer report
# ends the process that made it (halt_on_error), so it fails its test.
#
# Usage: bash deploy/sanitize.sh address|thread [extra ctest arguments]
#   address  AddressSanitizer with LeakSanitizer, and UndefinedBehaviorSanitizer: every test,
#            the fuzz corpora's replay among them. CI runs this (deploy/test.sh).
#   thread   ThreadSanitizer: the tests of the concurrent code (STEVI_TSAN_TESTS below).
# The build folder is build-asan or build-tsan beside build (STEVI_SANITIZE_BUILD_DIR overrides).
# The compiler is the project's g++; the reference data is read as by deploy/test.sh. Warnings
# are not errors here: the instrumented code gives g++ false ones, and deploy/test.sh's normal
# build is the one held to -Werror.
#
# Suppressions live in deploy/sanitizers/*.supp, each entry with the reason it is there. Only
# third-party code is suppressed. Debian's gRPC, protobuf, GLib and OpenCV are not built with
# the sanitizer: ThreadSanitizer cannot see their synchronisation, so a report whose every stack
# frame on one side is inside such a library is theirs to explain (see tsan.supp); a report with
# a stevi frame on both sides is ours, and is fixed, never suppressed.
set -euo pipefail
cd "$(dirname "$0")/.."
kind="${1:-}"
shift || true
case "$kind" in
  address) flags="address,undefined"; default_dir=build-asan ;;
  thread) flags="thread"; default_dir=build-tsan ;;
  *) echo "usage: bash deploy/sanitize.sh address|thread [ctest arguments]" >&2; exit 2 ;;
esac
build_dir="${STEVI_SANITIZE_BUILD_DIR:-$default_dir}"
supp="$PWD/deploy/sanitizers"
jobs="$(nproc)"

# -O1 -g1: the sanitizers' usual level. Line tables are all a report's stack needs, and the build
# takes much less time than with -O2 and full debug information.
build_start=$(date +%s)
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSTEVI_BUILD_TESTS=ON \
  -DSTEVI_BUILD_BENCHMARKS=OFF -DSTEVI_WERROR=OFF "-DSTEVI_SANITIZE=$flags" \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG"
cmake --build "$build_dir" -j"$jobs"
echo "sanitize.sh $kind: the build took $(( $(date +%s) - build_start )) s"

export ASAN_OPTIONS="halt_on_error=1:detect_leaks=1:strict_init_order=1:detect_stack_use_after_return=1"
export LSAN_OPTIONS="suppressions=$supp/lsan.supp:print_suppressions=0"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1:suppressions=$supp/ubsan.supp"
# history_size=7 (the largest): the older access of a race keeps its stack. With the default, a
# gRPC thread's access often came out as "failed to restore the stack", which no suppression
# can match, so a report of gRPC's own (race:libgrpc above) could not be told from ours.
# suppress_equal_addresses=0: TSan keeps every reported address in one list that it scans under
# a global lock before it looks at the suppressions. Each preview the station receives is parsed
# out of a new gRPC buffer, so a new address each time (a report of gRPC's, suppressed), and the
# station crawled until a page request waited a minute. Equal stacks are still reported once.
export TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:history_size=7:suppress_equal_addresses=0:suppressions=$supp/tsan.supp"
# The concurrent code: the engine, broadcaster and the rest of the server's runtime, the servers,
# the station and its Foxglove server, the Aravis source (the fake GigE camera), the MAVLink links
# and bridge, the client's streams and reconnect loop, the recording, the mailbox, the pose buffer.
STEVI_TSAN_TESTS='^(server/|client/|drivers/aravis/|drivers/recording/|drivers/mcap/|core/common/|core/geo/pose_buffer)'
# Not the GStreamer source's: Debian's GStreamer plugins are not instrumented, and their own
# hand-overs between streaming threads (through GLib's and GStreamer's locks) are reported as races
# by the dozen, one suppression per plugin library; its tests run under ASan (CI) instead.
STEVI_TSAN_EXCLUDED='^(server/gst_test|drivers/gstreamer/)'
select=()
if [[ "$kind" == thread ]]; then
  # One test at a time: each instrumented server already keeps both cores busy, and two of them
  # side by side starved each other into timeouts that say nothing about a race.
  select=(-R "$STEVI_TSAN_TESTS" -E "$STEVI_TSAN_EXCLUDED")
  jobs=1
fi
start=$(date +%s)
set +e
ctest --test-dir "$build_dir" --output-on-failure -j"$jobs" "${select[@]}" "$@" 2>&1 | tee "$build_dir/sanitize-$kind.log"
status=${PIPESTATUS[0]}
echo "sanitize.sh $kind: $(( $(date +%s) - start )) s of tests, exit $status"
exit "$status"
