#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine, builds stevi, starts stevi-server on its built-in synthetic
# rig and the ground station (`stevi station`: open the address it prints in a browser, or in
# Foxglove), and shows the live obstacles with `stevi watch` (Ctrl-C stops all three).
# Usage: bash deploy/demo.sh [watch flags, e.g. --json or --count 50]
# STEVI_DEMO_LISTEN picks the server's address (default 127.0.0.1:50051), STEVI_STATION_LISTEN
# the station's (default 127.0.0.1:8080).
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir="${STEVI_BUILD_DIR:-build}"
listen="${STEVI_DEMO_LISTEN:-127.0.0.1:50051}"
station_listen="${STEVI_STATION_LISTEN:-127.0.0.1:8080}"

bash deploy/install-deps.sh
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release
cmake --build "$build_dir" -j"$(nproc)" --target stevi-server stevi stevi-process

"$build_dir/bin/stevi-server" --listen "$listen" --data-dir "$build_dir/stevi-data" &
server_pid=$!
station_pid=
stop_all() {
  [ -n "$station_pid" ] && kill -TERM "$station_pid" 2>/dev/null
  kill -TERM "$server_pid" 2>/dev/null
  wait 2>/dev/null || true
}
trap stop_all EXIT INT TERM

# Wait for the server to answer (bounded: about 30 s).
for _ in $(seq 1 60); do
  if "$build_dir/bin/stevi" --server "$listen" --timeout 0.5 status >/dev/null 2>&1; then break; fi
  if ! kill -0 "$server_pid" 2>/dev/null; then echo "demo: stevi-server exited" >&2; exit 1; fi
  sleep 0.5
done
"$build_dir/bin/stevi" --server "$listen" status
# The ground station: it prints "stevi station: serving http://ADDRESS/" on its first line.
"$build_dir/bin/stevi" --server "$listen" station --listen "$station_listen" &
station_pid=$!
"$build_dir/bin/stevi" --server "$listen" watch "$@"
