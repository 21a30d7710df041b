#!/usr/bin/env bash
# The code checks of CI: every C++ file formatted as .clang-format says (clang-format --dry-run),
# the station page's scripts within .eslintrc.json's rules (eslint), and the sources (core,
# drivers, server, client; not the tests) within .clang-tidy's checks.
# Usage: bash deploy/check-code.sh [BUILD_DIR]   (a build configured with
#        -DCMAKE_EXPORT_COMPILE_COMMANDS=ON, as deploy/test.sh does; default ./build)
#        bash deploy/check-code.sh --format-only
# Fix the format with: clang-format -i $(git ls-files '*.cc' '*.h')
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir="${1:-build}"

mapfile -t all < <(git ls-files '*.cc' '*.h')
if ! clang-format --dry-run --Werror "${all[@]}" 2> /tmp/stevi-format.$$; then
  grep -E '^[^ ].*: error:' /tmp/stevi-format.$$ | cut -d: -f1 | sort -u | sed 's/^/  not formatted: /' >&2
  rm -f /tmp/stevi-format.$$
  echo "check-code: run clang-format -i on the files above" >&2
  exit 1
fi
rm -f /tmp/stevi-format.$$
echo "check-code: ${#all[@]} files formatted"

# The station's page (client/station/web/*.js, ES modules) within .eslintrc.json's rules, with
# Debian's eslint (deploy/install-deps.sh), which finds its plugins only through NODE_PATH.
web_scripts=(client/station/web/*.js)
if ! NODE_PATH=/usr/share/nodejs eslint --format unix --no-eslintrc -c .eslintrc.json \
    "${web_scripts[@]}" > /tmp/stevi-eslint.$$ 2>&1; then
  cat /tmp/stevi-eslint.$$ >&2
  rm -f /tmp/stevi-eslint.$$
  echo "check-code: eslint found the problems above in client/station/web (.eslintrc.json)" >&2
  exit 1
fi
rm -f /tmp/stevi-eslint.$$
echo "check-code: ${#web_scripts[@]} station page scripts within .eslintrc.json's rules"
[ "$build_dir" = "--format-only" ] && exit 0

if [ ! -f "$build_dir/compile_commands.json" ]; then
  echo "check-code: $build_dir/compile_commands.json missing (configure with -DCMAKE_EXPORT_COMPILE_COMMANDS=ON)" >&2
  exit 1
fi
mapfile -t sources < <(git ls-files 'core/*.cc' 'drivers/*.cc' 'server/*.cc' 'client/*.cc')
# GCC's -Wshadow=local is unknown to clang: not a finding.
if ! printf '%s\n' "${sources[@]}" | xargs -P "$(nproc)" -n 4 \
    clang-tidy -p "$build_dir" --quiet --extra-arg=-Wno-unknown-warning-option 2> /dev/null \
    > /tmp/stevi-tidy.$$; then
  grep -E 'error:|note: [0-9]+ lines' /tmp/stevi-tidy.$$ >&2 || cat /tmp/stevi-tidy.$$ >&2
  rm -f /tmp/stevi-tidy.$$
  echo "check-code: clang-tidy found the problems above (.clang-tidy)" >&2
  exit 1
fi
rm -f /tmp/stevi-tidy.$$
echo "check-code: ${#sources[@]} sources within .clang-tidy's checks"
