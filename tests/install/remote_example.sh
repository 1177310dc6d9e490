#!/usr/bin/env bash
# Runs example 4 against the INSTALLED softshell-server: starts it on a free port, reads the URL it
# prints, runs the example with it, stops the server.
set -euo pipefail
server=$1 example=$2
out=$(mktemp)
trap 'kill "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; rm -f "$out"' EXIT
"$server" --host 127.0.0.1 --port 0 --log-level warning >"$out" 2>&1 &
pid=$!
url=""
for _ in $(seq 1 200); do
  url=$(grep -o 'http://127.0.0.1:[0-9]*' "$out" | head -n1 || true)
  [ -n "$url" ] && break
  kill -0 "$pid" 2>/dev/null || { cat "$out" >&2; echo "softshell-server exited" >&2; exit 1; }
  sleep 0.05
done
[ -n "$url" ] || { cat "$out" >&2; echo "softshell-server printed no URL" >&2; exit 1; }
"$example" "$url"
