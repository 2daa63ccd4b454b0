#!/usr/bin/env bash
# Whole-body balance (issue 9): data, models, sampling accuracy/coverage and the reach benchmark, both robots.
#
#     bash benchmarks/bench_balance.sh [OUT=runs/balance] [ROBOTS="talos centauro"] [RUNS=10] [TIME=30]
#
# Per robot: collect 2,500 stable configurations per pelvis/base height (seed 0), train a CVAE and a CGAN
# (their defaults: residual penalty on the feet/height equalities and on the CoM-margin inequality), score
# them per condition (`bench sampling`: raw and refined accuracy = equalities within tolerance AND CoM
# inside the polygon with its margin; coverage against fresh projection samples), then plan the reach
# scene RUNS times with every method (`bench plan`; results.md holds the planning table and the static
# stability of every solved path). Finished steps are skipped when rerun (bench plan resumes).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-runs/balance}
robots=${2:-talos centauro}
runs=${3:-10}
time=${4:-30}
mg=(.venv/bin/manifoldgen)
[ -x "${mg[0]}" ] || mg=(manifoldgen)
mkdir -p "$out"
for r in $robots; do
  d="$out/$r"
  [ -f "$d.npz" ] || "${mg[@]}" collect balance --robot "$r" --per-condition 2500 --seed 0 -o "$d.npz"
  for m in cvae cgan; do
    [ -f "$d-$m/model.json" ] || "${mg[@]}" train "$d.npz" --model "$m" --seed 0 -o "$d-$m"
  done
  [ -f "$out/sampling-$r/table.md" ] || "${mg[@]}" bench sampling "$d-cvae" "$d-cgan" -o "$out/sampling-$r" \
      --samples 1000 --reference 1000 --repeats 3 --threads 1
  "${mg[@]}" bench plan balance --robot "$r" --scene reach --runs "$runs" --time "$time" --workers 2 --resume \
    --set pool=32 --set pool_batch=64 -o "$out/plan-$r" \
    -m "cvae-rrtconnect=rrtconnect@cvae:$d-cvae,batch=256" -m "cvae-rrt=rrt@cvae:$d-cvae,batch=256" \
    -m "cvae-kpiece=kpiece@cvae:$d-cvae,batch=256" -m "project-rrtconnect=rrtconnect@project" \
    -m "cbirrt=cbirrt:project@uniform" -m "ompl-projected=ompl-projected-rrtconnect" \
    -m "ompl-atlas=ompl-atlas-rrtconnect" -m "blind=rrtconnect:direct@blind" \
    -m "cgan-rrtconnect=rrtconnect@cgan:$d-cgan,batch=256" -m "feet-only=rrtconnect@feet-only"
done
