# Sourced by the test scripts that need a softshell-server. `start_server SERVER [OPTION...]` starts
# it on a free port of 127.0.0.1 with the extra options given, sets `url` to the address it prints
# and `server_pid` to its process; at exit the server is stopped and the files listed in
# `remove_on_exit` are removed. (The log file exists before the server starts: a redirection in a
# background job is opened by the child, possibly after the first poll.)
remove_on_exit=()
stop_server() {
  if [ -n "${server_pid:-}" ]; then
    kill "$server_pid" 2>/dev/null || true
    wait "$server_pid" 2>/dev/null || true
  fi
  rm -f "${remove_on_exit[@]}"
}
start_server() {
  local server=$1 log
  shift
  log=$(mktemp)
  remove_on_exit+=("$log")
  trap stop_server EXIT
  "$server" --host 127.0.0.1 --port 0 --log-level warning "$@" >"$log" 2>&1 &
  server_pid=$!
  url=""
  for _ in $(seq 1 200); do
    url=$(grep -o 'http://127.0.0.1:[0-9]*' "$log" | head -n1 || true)
    [ -n "$url" ] && return 0
    kill -0 "$server_pid" 2>/dev/null || { cat "$log" >&2; echo "softshell-server exited" >&2; exit 1; }
    sleep 0.05
  done
  cat "$log" >&2
  echo "softshell-server printed no URL" >&2
  exit 1
}
