#!/usr/bin/env bash
# The whole aoc flow on a built-in task, in a throwaway store. Run by `make demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
AOC=.venv/bin/aoc
export AOC_STORE="${AOC_STORE:-$(mktemp -d)/corpora}"
echo "demo store: $AOC_STORE" >&2
$AOC --help >/dev/null
echo "aoc is installed; more of the flow arrives with the next issues." >&2
