#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine, builds stevi, starts stevi-server on its built-in synthetic
# rig and shows the live obstacles with `stevi watch` (Ctrl-C stops both).
# Usage: bash deploy/demo.sh [watch flags, e.g. --json or --count 50]
# STEVI_DEMO_LISTEN picks the address (default 127.0.0.1:50051).
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir="${STEVI_BUILD_DIR:-build}"
listen="${STEVI_DEMO_LISTEN:-127.0.0.1:50051}"

bash deploy/install-deps.sh
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release
cmake --build "$build_dir" -j"$(nproc)" --target stevi-server stevi stevi-process

"$build_dir/bin/stevi-server" --listen "$listen" --data-dir "$build_dir/stevi-data" &
server_pid=$!
trap 'kill -TERM "$server_pid" 2>/dev/null; wait "$server_pid" 2>/dev/null || true' EXIT INT TERM

# Wait for the server to answer (bounded: about 30 s).
for _ in $(seq 1 60); do
  if "$build_dir/bin/stevi" --server "$listen" --timeout 0.5 status >/dev/null 2>&1; then break; fi
  if ! kill -0 "$server_pid" 2>/dev/null; then echo "demo: stevi-server exited" >&2; exit 1; fi
  sleep 0.5
done
"$build_dir/bin/stevi" --server "$listen" status
"$build_dir/bin/stevi" --server "$listen" watch "$@"
