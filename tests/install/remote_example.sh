#!/usr/bin/env bash
# Runs example 4 against the INSTALLED softshell-server: starts it on a free port, reads the URL it
# prints, runs the example with it, stops the server.
set -euo pipefail
server=$1 example=$2
source "$(dirname "$0")/../support/start_server.sh"
start_server "$server"
"$example" "$url"
