#!/usr/bin/env bash
# Starts softshell-server with a token file on a free port of 127.0.0.1 and runs the plain-C test
# of the remote session's auth_token against it. Usage: c_api_remote_auth_test.sh SERVER TEST
set -euo pipefail
server=$1 test=$2
source "$(dirname "$0")/../support/start_server.sh"
token_file=$(mktemp)
remove_on_exit+=("$token_file")
token=c-abi-token-0123456789abcdef
printf '%s\n' "$token" >"$token_file"
chmod 600 "$token_file"
start_server "$server" --threads 1 --auth-token-file "$token_file"
"$test" "$url" "$token"
