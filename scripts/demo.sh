#!/usr/bin/env bash
# The whole aoc flow on the heterogeneous pendulum, in a throwaway store. Run by `make demo`.
#   collect -> info -> train -> index -> rollout (upright, with an audit log; random start) -> explain
set -euo pipefail
cd "$(dirname "$0")/.."
AOC=.venv/bin/aoc
export AOC_STORE="${AOC_STORE:-$(mktemp -d)/corpora}"
OUT="${DEMO_OUT:-$(dirname "$AOC_STORE")}"
step() { printf '\n\033[1m== %s\033[0m\n' "$*" >&2; }

step "collect 30k rows of behaviour data on pendulum-het (store: $AOC_STORE)"
$AOC collect pendulum-het --steps 30000 --name pendulum --seed 0 --format table

step "what is in the corpus"
$AOC info pendulum --format table

step "train the belief model (value mode: discounted return-to-go; the auxiliary dynamics head tells the two systems apart)"
$AOC train pendulum --seed 0 --dynamics-weight 1 --format table

step "beliefs of every row and the nearest-neighbour index"
$AOC index pendulum --format table

step "run the controller for 3 episodes from the paper's upright start (normal system), with an audit log"
$AOC rollout pendulum --env pendulum-het-upright --episodes 3 --seed 100 \
    --audit "$OUT/audit.h5" --plot "$OUT/rollout.png" --format table

step "the same controller from a random start: a swing-up, which AOC does not solve (docs/notes/belief.md)"
$AOC rollout pendulum --env pendulum-het --episodes 2 --seed 100 --format table

step "explain the decision at step 50 of episode 0, from the audit log (and its page: the episode's overview, the decision's supporting rows)"
$AOC explain pendulum --audit "$OUT/audit.h5" --episode 0 --step 50 --format table \
    --html "$OUT/decision.html"

echo >&2
echo "demo done: store $AOC_STORE, audit log $OUT/audit.h5, plot $OUT/rollout.png, page $OUT/decision.html" >&2
