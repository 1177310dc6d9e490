#!/usr/bin/env bash
# Runs a shell block extracted from the docs, verbatim, against a fresh softshell-server on a free
# port (exported as SOFTSHELL), then checks its output against the block's own comments: every
# comment "# {...}" or "# [...]" (on its own line or after a command) is an expected output, in
# order, where "..." stands for anything. So the outputs the docs show are checked too.
#   run_shell_block.sh SERVER BLOCK
set -euo pipefail
server=$1 block=$2
source "$(dirname "$0")/../support/start_server.sh"
start_server "$server"
out=$(mktemp)
remove_on_exit+=("$out")

if ! SOFTSHELL=$url bash -euo pipefail "$block" >"$out"; then
  echo "the block $block failed; its output:" >&2
  cat "$out" >&2
  exit 1
fi

# The expectations, as one Perl regex: literal pieces (\Q...\E) joined by .*? at each "...".
pattern='(?s)'
count=0
while IFS= read -r expected; do
  piece=""
  rest=$expected
  while [[ $rest == *"..."* ]]; do
    piece+="\\Q${rest%%...*}\\E.*?"
    rest=${rest#*...}
  done
  piece+="\\Q${rest}\\E"
  pattern+="${piece}.*?"
  count=$((count + 1))
done < <(grep -oP '(^|\s)#\s\K[{\[].*$' "$block")
[ "$count" -gt 0 ] || { echo "$block has no expected outputs (# {...} comments)" >&2; exit 1; }
if ! grep -qPz -- "$pattern" "$out"; then
  echo "the output of $block does not show what its comments say ($count expectations, in order)." >&2
  echo "expected, in order:" >&2
  grep -oP '(^|\s)#\s\K[{\[].*$' "$block" >&2
  echo "got:" >&2
  cat "$out" >&2
  exit 1
fi
echo "$block: ran against $url; its $count shown outputs match"
