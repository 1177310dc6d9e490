#!/usr/bin/env bash
# Starts softshell-server with a token file on a free port of 127.0.0.1 and runs the plain-C test
# of the remote session's auth_token against it. Usage: c_api_remote_auth_test.sh SERVER TEST
set -euo pipefail
server=$1 test=$2
dir=$(mktemp -d)
token=c-abi-token-0123456789abcdef
printf '%s\n' "$token" >"$dir/token"
chmod 600 "$dir/token"
"$server" --host 127.0.0.1 --port 0 --threads 1 --log-level warning --auth-token-file "$dir/token" >"$dir/out" 2>&1 &
pid=$!
trap 'kill $pid 2>/dev/null || true; wait $pid 2>/dev/null || true; rm -rf "$dir"' EXIT
url=""
for _ in $(seq 1 200); do
  url=$(sed -n 's/^softshell-server listening on \(http:[^ ]*\)$/\1/p' "$dir/out")
  [ -n "$url" ] && break
  kill -0 $pid 2>/dev/null || { cat "$dir/out" >&2; exit 1; }
  sleep 0.05
done
[ -n "$url" ] || { echo "softshell-server did not start" >&2; cat "$dir/out" >&2; exit 1; }
"$test" "$url" "$token"
