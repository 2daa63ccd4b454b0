#!/usr/bin/env bash
# Whole-body balance (issue 9): every figure of the README's "Whole-body balance" section, one command.
#
#     bash benchmarks/bench_balance.sh [OUT=runs/balance] [RUNS=30] [TIME=30] [STEPS="reach others drinkcan"] [WORKERS=1]
#
# reach (per robot, talos then centauro): collect 2,500 stable configurations per pelvis/base height (seed 0),
#   train a CVAE (its default: residual penalty on the equalities, penalty on the CoM-margin inequality), score
#   it per condition (accuracy = equalities within tolerance AND CoM inside with its margin; talos also coverage
#   against fresh projection samples, `bench sampling`), then plan the reach scene RUNS times (seeds 0..RUNS-1) with the
#   learned sampler + RRT-Connect and the balance-blind planner, every solved path checked for static stability
#   state by state and executed in MuJoCo (`--physics`); WORKERS processes (1: the times are one process's).
# others: the other planners on the same reach scenes, 10 seeds each, one worker: the learned sampler with SBL,
#   RRT and KPIECE; uniform + projection with RRT-Connect; CBiRRT; OMPL Projected / Atlas; the CoM-blind planner.
# drinkcan: collect 2,500 upright-can configurations per wrist yaw, train a CVAE with a 4-dimensional latent (the
#   manifold's dimension: 7 joints - 2 upright - 1 wrist joint held), plan the drinkcan scene DRINKCAN_RUNS times
#   (default 10) with the learned sampler + RRT-Connect, uniform + projection + RRT-Connect, CBiRRT and OMPL Atlas;
#   sample accuracy per yaw; one learned-sampler path with its snapshots (docs/images/drinkcan.png), rechecked by
#   examples/check_path.py. The reach step ends with the README's snapshots.
# The README's figures: talos RUNS=30 WORKERS=1; centauro's reach with RUNS=20 WORKERS=2 (its physics checks are dear).
# Finished steps are skipped when rerun (`bench plan` resumes); results.md in each plan folder holds the tables.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-runs/balance}
runs=${2:-30}
time=${3:-30}
steps=${4:-reach others drinkcan}
workers=${5:-1}
mg=(.venv/bin/manifoldgen)
[ -x "${mg[0]}" ] || mg=(manifoldgen)
py=.venv/bin/python
[ -x "$py" ] || py=python
mkdir -p "$out"
settings=(--set pool=32 --set pool_batch=64)
model() {  # model TASK ROBOT NAME: dataset and CVAE
  [ -f "$out/$3.npz" ] || "${mg[@]}" collect "$1" --robot "$2" --per-condition 2500 --seed 0 -o "$out/$3.npz"
  [ -f "$out/$3-cvae/model.json" ] || "${mg[@]}" train "$out/$3.npz" --model cvae --seed 0 -o "$out/$3-cvae"
}
for r in talos centauro; do
  case " $steps " in *" reach "*|*" others "*) model balance "$r" "$r" ;; esac
  cvae="$out/$r-cvae"
  if [[ " $steps " == *" reach "* ]]; then
    if [ "$r" = talos ]; then  # accuracy and coverage against fresh projection samples
      [ -f "$out/sampling-$r/table.md" ] || "${mg[@]}" bench sampling "$cvae" -o "$out/sampling-$r" \
          --samples 1000 --reference 1000 --repeats 1 --threads 1
    else  # accuracy only: centauro's reference samples would take ~1 h to collect (4 rows/s)
      for y in 0.7 0.75 0.8 0.85; do
        "${mg[@]}" sample "$cvae" --condition="$y" -n 1000 --refine 2 -o "$out/samples-$r-$y.npz"
      done
    fi
    "${mg[@]}" bench plan balance --robot "$r" --scene reach --runs "$runs" --time "$time" --workers "$workers" --resume \
      "${settings[@]}" --physics -o "$out/plan-$r" \
      -m "cvae-rrtconnect=rrtconnect@cvae:$cvae,batch=256" -m "blind=rrtconnect:direct@blind"
  fi
  if [[ " $steps " == *" others "* ]]; then
    "${mg[@]}" bench plan balance --robot "$r" --scene reach --runs 10 --time "$time" --workers 1 --resume \
      "${settings[@]}" -o "$out/others-$r" \
      -m "cvae-sbl=sbl@cvae:$cvae,batch=256" -m "cvae-rrt=rrt@cvae:$cvae,batch=256" \
      -m "cvae-kpiece=kpiece@cvae:$cvae,batch=256" -m "project-rrtconnect=rrtconnect@project" \
      -m "cbirrt=cbirrt:project@uniform" -m "ompl-projected=ompl-projected-rrtconnect" \
      -m "ompl-atlas=ompl-atlas-rrtconnect" -m "feet-only=rrtconnect@feet-only"
  fi
done
if [[ " $steps " == *" drinkcan "* ]]; then
  # latent 4, not the CVAE's default 3: a decoder from a 3-dimensional latent covers a 3-dimensional sheet of this
  # 4-dimensional manifold, and RRT-Connect's goal tree found no samples near the goal (README, drinkcan)
  dc="$out/drinkcan-cvae4"
  [ -f "$out/drinkcan.npz" ] || "${mg[@]}" collect drinkcan --per-condition 2500 --seed 0 -o "$out/drinkcan.npz"
  [ -f "$dc/model.json" ] || "${mg[@]}" train "$out/drinkcan.npz" --model cvae --set latent=4 --seed 0 -o "$dc"
  "${mg[@]}" bench plan drinkcan --scene drinkcan --runs "${DRINKCAN_RUNS:-10}" --time "$time" --workers 1 --resume \
    -o "$out/plan-drinkcan" -m "cvae-rrtconnect=rrtconnect@cvae:$dc,batch=256" -m "project-rrtconnect=rrtconnect@project" \
    -m "cbirrt=cbirrt:project@uniform" -m "ompl-atlas=ompl-atlas-rrtconnect"
  for y in -0.75 -0.25 0.25 0.75; do
    "${mg[@]}" sample "$dc" --condition="$y" -n 1000 --refine 2 -o "$out/samples-drinkcan-$y.npz"
  done
  "${mg[@]}" plan drinkcan --scene drinkcan --sampler "cvae:$dc,batch=256" --seed 0 --time 30 \
    -o "$out/drinkcan-path.npz" --snapshots docs/images/drinkcan.png
  "$py" examples/check_path.py "$out/drinkcan-path.npz"
fi
if [[ " $steps " == *" reach "* ]]; then  # the README's snapshots, each path rechecked from its file alone
  for r in talos centauro; do
    "${mg[@]}" plan balance --robot "$r" --scene reach --sampler "cvae:$out/$r-cvae,batch=256" "${settings[@]}" \
      --seed 1 -o "$out/$r-reach.npz" --snapshots "docs/images/balance-$r-reach.png"
    "$py" examples/check_path.py "$out/$r-reach.npz"
  done
fi
