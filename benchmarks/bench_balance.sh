#!/usr/bin/env bash
# Whole-body balance: every figure of the README's "Whole-body balance" section, one command.
#
#     bash benchmarks/bench_balance.sh [OUT=runs/balance] [RUNS=30] [TIME=30] [STEPS="reach others drinkcan"] [WORKERS=1]
#                                      [ROBOTS="talos centauro"]
#
# reach (per robot, talos then centauro): collect stable configurations per pelvis/base height (seed 0; talos 2,500
#   per height from uniform seeds; centauro 5,000 per height, 20,000 as in the paper, from seeds normal around the
#   stance, sd 1 rad: uniform seeds converge at 4 rows/s with the wheels upright), train a CVAE (its default: residual
#   penalty on the equalities, penalty on the CoM-margin inequality; centauro 30 epochs on its 20,000 rows), score it
#   per condition (accuracy = equalities within tolerance AND CoM inside with its margin; talos: `bench sampling`,
#   coverage against fresh projection samples; centauro: raw, 1 and 2 projection steps, coverage against a fresh
#   collection made as its data was, sampling-centauro/table.md), then plan the reach scene RUNS times (seeds
#   0..RUNS-1) with the learned sampler + RRT-Connect and the balance-blind planner, every solved path checked for
#   static stability state by state and executed in MuJoCo (`--physics`); WORKERS processes (1: one process's times).
# others: the other planners on the same reach scenes, 10 seeds each, one worker: the learned sampler with SBL,
#   RRT and KPIECE; uniform + projection with RRT-Connect; CBiRRT; OMPL Projected / Atlas; the CoM-blind planner.
# drinkcan: collect 2,500 upright-can configurations per wrist yaw, train a CVAE with a 4-dimensional latent (the
#   manifold's dimension: 7 joints - 2 upright - 1 wrist joint held), plan the drinkcan scene DRINKCAN_RUNS times
#   (default 10) with the learned sampler + RRT-Connect, uniform + projection + RRT-Connect, CBiRRT and OMPL Atlas;
#   sample accuracy per yaw; one learned-sampler path with its snapshots (docs/images/drinkcan.png), rechecked by
#   examples/check_path.py. The reach step ends with the README's snapshots, each path rechecked by
#   examples/check_path.py.
# The README's figures: talos RUNS=30 WORKERS=1; centauro (ROBOTS=centauro, STEPS="reach others") RUNS=30 WORKERS=2
# (its physics checks are dear), its other planners with 2 workers too; drinkcan DRINKCAN_RUNS=30.
# Finished steps are skipped when rerun (`bench plan` resumes); results.md in each plan folder holds the tables.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-runs/balance}
runs=${2:-30}
time=${3:-30}
steps=${4:-reach others drinkcan}
workers=${5:-1}
robots=${6:-talos centauro}
mg=(.venv/bin/manifoldgen)
[ -x "${mg[0]}" ] || mg=(manifoldgen)
py=.venv/bin/python
[ -x "$py" ] || py=python
mkdir -p "$out"
settings=(--set pool=32 --set pool_batch=64)
model() {  # model TASK ROBOT NAME [COLLECT OPTIONS] [-- TRAIN OPTIONS]: dataset and CVAE
  local task=$1 robot=$2 name=$3 collect=() train=()
  shift 3
  while [ $# -gt 0 ] && [ "$1" != -- ]; do collect+=("$1"); shift; done
  [ ${#collect[@]} -gt 0 ] || collect=(--per-condition 2500)
  [ $# -gt 0 ] && shift && train=("$@")
  [ -f "$out/$name.npz" ] || "${mg[@]}" collect "$task" --robot "$robot" "${collect[@]}" --seed 0 -o "$out/$name.npz"
  [ -f "$out/$name-cvae/model.json" ] || "${mg[@]}" train "$out/$name.npz" --model cvae --seed 0 "${train[@]}" \
      -o "$out/$name-cvae"
}
near=1.0  # centauro: seeds normal around the stance, sd in rad (and m for the base position)
for r in $robots; do
  case " $steps " in *" reach "*|*" others "*)
    if [ "$r" = talos ]; then model balance talos talos
    else model balance centauro centauro --per-condition 5000 --near-home "$near" -- --epochs 30 \
        --set latent=8 --set "hidden=[256,256]"; fi ;;
  esac
  cvae="$out/$r-cvae"
  if [[ " $steps " == *" reach "* ]]; then
    if [ "$r" = talos ]; then  # accuracy and coverage against fresh projection samples
      [ -f "$out/sampling-$r/table.md" ] || "${mg[@]}" bench sampling "$cvae" -o "$out/sampling-$r" \
          --samples 1000 --reference 1000 --repeats 1 --threads 1
    elif [ ! -f "$out/sampling-$r/table.md" ]; then  # accuracy raw / 1 / 2 projection steps, and coverage against
      # a fresh collection made as the data was (seeds around the stance; `bench sampling`'s uniform-seed reference
      # would take ~1 h at 4 rows/s), at the training heights and between them
      mkdir -p "$out/sampling-$r"
      "$py" - "$cvae" "$out/sampling-$r" "$near" <<'PY'
import json, sys
import numpy as np, torch
from manifoldgen.metrics import accuracy, coverage_metrics
from manifoldgen.data import collect
from manifoldgen.models import load_model
from manifoldgen.tasks import task_from_meta
model = load_model(sys.argv[1]); task = task_from_meta(model.meta); robot = task.robot
rows, gen = [], torch.Generator().manual_seed(0)
for i, (y, seen) in enumerate([(0.7, 1), (0.75, 1), (0.8, 1), (0.85, 1), (0.725, 0), (0.775, 0), (0.825, 0)]):
    q = model.sample([y], 1000, gen); ys = np.full((1000, 1), y)
    raw1, _ = accuracy(task.constraint, q, ys, 1); raw2, _ = accuracy(task.constraint, q, ys, 2)
    ref = collect(task, 1000, 1000 + i, conditions=[[y]], near_home=float(sys.argv[3]), progress=False).q
    cov = coverage_metrics(ref, q, robot.lower, robot.upper)
    rows.append({"height": y, "seen": bool(seen), "raw": raw1.raw, "refine1": raw1.refined, "refine2": raw2.refined,
                 **cov})
    print(rows[-1], flush=True)
json.dump(rows, open(f"{sys.argv[2]}/results.json", "w"), indent=1)
lines = ["| height m | seen | within tolerance raw | after 1 step | after 2 steps | coverage | precision | recall |",
         "|---|---|---|---|---|---|---|---|"]
lines += [f"| {r['height']:g} | {'yes' if r['seen'] else 'no'} | {100 * r['raw']:.1f} % | {100 * r['refine1']:.1f} % | "
          f"{100 * r['refine2']:.1f} % | {r['coverage']:.2f} | {r['precision']:.2f} | {r['recall']:.2f} |" for r in rows]
open(f"{sys.argv[2]}/table.md", "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
PY
    fi
    "${mg[@]}" bench plan balance --robot "$r" --scene reach --runs "$runs" --time "$time" --workers "$workers" --resume \
      "${settings[@]}" --physics -o "$out/plan-$r" \
      -m "cvae-rrtconnect=rrtconnect@cvae:$cvae,batch=256" -m "blind=rrtconnect:direct@blind"
  fi
  if [[ " $steps " == *" others "* ]]; then
    others=(-m "cvae-sbl=sbl@cvae:$cvae,batch=256" -m "cvae-rrt=rrt@cvae:$cvae,batch=256"
            -m "cvae-kpiece=kpiece@cvae:$cvae,batch=256" -m "project-rrtconnect=rrtconnect@project"
            -m "cbirrt=cbirrt:project@uniform" -m "ompl-atlas=ompl-atlas-rrtconnect")
    if [ "$r" = talos ]; then
      others+=(-m "ompl-projected=ompl-projected-rrtconnect" -m "feet-only=rrtconnect@feet-only")
      w=1
    else
      w=$workers
    fi
    "${mg[@]}" bench plan balance --robot "$r" --scene reach --runs 10 --time "$time" --workers "$w" --resume \
      "${settings[@]}" -o "$out/others-$r" "${others[@]}"
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
  for r in $robots; do
    "${mg[@]}" plan balance --robot "$r" --scene reach --sampler "cvae:$out/$r-cvae,batch=256" "${settings[@]}" \
      --seed 1 -o "$out/$r-reach.npz" --snapshots "docs/images/balance-$r-reach.png"
    "$py" examples/check_path.py "$out/$r-reach.npz"
  done
fi
