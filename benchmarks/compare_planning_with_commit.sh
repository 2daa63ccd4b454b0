#!/usr/bin/env bash
# Wall and maze planning with the shipped CVAE, this tree against an earlier commit, interleaved in one run.
#
#     bash benchmarks/compare_planning_with_commit.sh [COMMIT=5cb5b63] [RUNS=20] [ROUNDS=2] [all]
#
# The earlier commit is checked out into a temporary worktree and run with the same venv (its
# src/ first on PYTHONPATH); each side uses its own shipped model and its default planner settings.
# Prints bench_planning_quick's table (success, mean/median/max wall time, mean CPU time) per round
# and side: the shipped CVAE only, or with `all` bench_planning_quick's default samplers (project, pg, cvae).
set -euo pipefail
cd "$(dirname "$0")/.."
commit=${1:-5cb5b63}
runs=${2:-20}
rounds=${3:-2}
samplers=(--sampler "cvae:src/manifoldgen/data/pretrained/panda-pose-cvae")
[ "${4:-}" = all ] && samplers=()
old=$(mktemp -d)
trap 'git worktree remove --force "$old" >/dev/null 2>&1 || true' EXIT
git worktree add -q --detach "$old" "$commit"
for round in $(seq "$rounds"); do
  echo "== round $round: $commit"
  (cd "$old" && PYTHONPATH="$old/src" "$OLDPWD/.venv/bin/python" benchmarks/bench_planning_quick.py \
     --runs "$runs" --scenes wall maze "${samplers[@]}")
  echo "== round $round: this tree"
  .venv/bin/python benchmarks/bench_planning_quick.py --runs "$runs" --scenes wall maze "${samplers[@]}"
done
