"""The sixth hostile round's fix set as a table: each case that was refused cleanly, and each one since fixed into a
refusal, must be refused in one line naming the problem and the fix, exit code 2, nothing written, no input changed
(tests/refusals.py); a few cases accepted correctly must still work. The inputs are made once per module, in this
process, by round6/fixtures.py (a few seconds). A case with a set-up (a user's file, link, pipe or a second
writer's lock beside the output) runs it in the case's folder, which a refusal must leave as it was.

Left out, with the reason:
  needs the network: view-host-unresolvable (a host name lookup)
  now accepted, read by tests/test_hostile_round6.py: collect-task-bom-toml, tasks-bom
  needs a process of its own (test_hostile_round6.py): collect-stdout-ascii (PYTHONIOENCODING=ascii),
    check-bench-empty-runs (examples/check_path.py)
  signals a process of its own: collect-sigint-resume-identical, plan-kill9-roadmap-then-rerun
  shows what a fresh process imports (here the libraries are imported already): train-dataset-task-file-shadows,
    train-task-file-folder-shadows, sample-model-task-file-shadows, view-task-folder-shadows,
    view-path-task-file-shadows, physics-task-file-shadows, bench-sampling-task-file-shadows
  reads the environment once per process: plan-tmpdir-missing (TMPDIR), plan-cwd-deleted (this process's folder)
  slow (a collision matrix recomputed, a residual that sleeps): collect-cache-is-a-file, collect-cache-damaged,
    plan-user-slow-residual
  needs a larger dataset than the 30 rows here to solve (unsolved after 10 s): api-plan-with-dataset-object
  runs the examples' checkers as scripts: check-bench-resolution-zero, check-bench-user-type,
    check-path-resolution-zero, check-path-through-wall, check-path-start-moved, check-path-joints-swapped,
    check-path-urdf-sha, check-dataset-outside-limits, check-dataset-on-a-path, check-roadmap-on-a-path,
    check-roadmap-edge-through-wall
Run here without the shell they had: plan-scene-type-code without PYTHONPATH (the refusal names the type unimported),
the two-writer cases against a lock held in this process, bench-workers-five on two CPUs, robots-name-dotdot from the
case's folder.
"""

from __future__ import annotations

import fcntl
import json
import os

import numpy as np
import pytest
from typer.testing import CliRunner

import manifoldgen as mg
from manifoldgen.dataset import Dataset
from manifoldgen.runtime import set_threads
from refusals import api, cli, copied, ran, refused_after, within
from round6 import fixtures

pytestmark = pytest.mark.slow
runner = CliRunner()
RESUME = "train {I}/data.npz " + " ".join(fixtures.TRAIN) + " --resume"
WALL = "plan pose --scene wall --time 10 --no-picture"
BENCH = "bench plan pose --scene wall --runs 1 --time 2"
SAMPLING = "bench sampling {I}/model --samples 100 --reference 100 --repeats 1"


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, planned_path):
    """Every input of the cases (round6/fixtures.py)."""
    root = tmp_path_factory.mktemp("round6")
    fixtures.make(root, planned_path("wall"))
    return root


CASES = [
    cli("collect-per-condition-zero", "collect pose --per-condition 0 -o {O}/d.npz",
        "--per-condition must be positive, got 0"),
    cli("collect-per-condition-billion", "collect pose --per-condition 1000000000 -o {O}/d.npz",
        "1000000000 rows per condition at 6 condition value(s) make more than 10,000,000 rows; collect several "
        "smaller datasets"),
    cli("collect-output-is-dir", "collect pose --per-condition 20 -o {O}/d.npz",
        "-o {O}/d.npz is a folder, but a file is meant here; give a file path such as {O}/d.npz/out.npz"),
    cli("collect-output-txt-suffix", "collect pose --per-condition 20 -o {O}/d.txt",
        "-o must end in .npz, got {O}/d.txt; give a name such as d.npz"),
    cli("collect-output-in-sys", "collect pose --per-condition 20 -o /sys/d.npz",
        "cannot write /sys/d.npz: Permission denied; choose a writable location (nothing was written)"),
    cli("collect-lock-is-a-dir", "collect pose --per-condition 20 -o {O}/d.npz",
        "cannot write {O}/d.npz.lock: Is a directory; check the path (nothing was written)"),
    cli("collect-two-writers", "collect pose --per-condition 100000 --seed 9 -o {O}/a.npz",
        "(lock {O}/a.npz.lock); wait for it to finish or choose another output"),
    cli("collect-task-binary-toml", "collect {I}/tasks/binary.toml -o {O}/d.npz",
        "{I}/tasks/binary.toml is a binary file, not a task file (TOML text); give a .toml task file"),
    cli("collect-task-is-a-dataset", "collect {I}/data.npz -o {O}/d.npz",
        "{I}/data.npz is a zip archive (an .npz dataset, path or roadmap?), not a task file (TOML text); give a .toml"),
    cli("collect-robot-with-task-file",
        "collect {I}/tasks/builtin-only.toml --robot pr2 --per-condition 20 -o {O}/d.npz",
        "is for robot 'panda', not 'pr2'; drop --robot (a task file names its robot) or edit the file's 'robot'"),
    cli("collect-values-1e308", "collect {I}/tasks/values-1e308.toml --per-condition 20 -o {O}/d.npz",
        "home_condition [0.45] is outside the task's condition values (panda_hand_tcp.z in [0.5, 1e+308] m); give a "
        "home_condition inside them"),
    cli("collect-user-sys-exit", "collect {I}/user/u_exit.toml --per-condition 20 -o {O}/d.npz",
        "user code {I}/user/u_exit.py, line 10 called exit(0) while its task was read"),
    cli("collect-user-nan-residual", "collect {I}/user/u_nan.toml --per-condition 20 -o {O}/d.npz",
        "the residual of constraint u_nan:Tool holds NaN or infinite values; fix its residual()"),
    cli("collect-user-recursion", "collect {I}/user/u_recursion.toml --per-condition 20 -o {O}/d.npz",
        "user code {I}/user/u_recursion.py, line 13 raised RecursionError: maximum recursion depth exceeded"),
    cli("collect-user-class-missing", "collect {I}/user/class-missing.toml --per-condition 20 -o {O}/d.npz",
        "{I}/user/class-missing.toml, line 4: constraint 1: module 'u_ok' has no 'Nope' (for constraint 'u_ok:Nope'); "
        "check the name"),
    cli("collect-user-no-class-name", "collect {I}/user/no-class.toml --per-condition 20 -o {O}/d.npz",
        "'u_ok:' is not a constraint name nor 'module:Class'; write e.g. 'my_module:MyClass'"),
    cli("collect-stdlib-class", "collect {I}/tasks/stdlib-class.toml --per-condition 20 -o {O}/d.npz",
        "'json:JSONDecoder' is not a Constraint subclass; a constraint class must subclass manifoldgen's Constraint"),
    cli("collect-task-fifo", "collect {O}/t.toml -o {O}/d.npz",
        "task file {O}/t.toml is not a regular file (a device, pipe or socket); give a .toml task file"),
    cli("train-epochs-zero", "train {I}/data.npz --model cvae --epochs 0 --set hidden=[8] -o {O}/m",
        "--epochs must be from 1 to 100000, got 0"),
    cli("train-lr-negative", "train {I}/data.npz --model cvae --epochs 1 --set hidden=[8] --set lr=-0.001 -o {O}/m",
        "hyper-parameter lr=-0.001 of model 'cvae' must be a number in (0, 10] (default 0.001)"),
    cli("train-batch-zero", "train {I}/data.npz --model cvae --epochs 1 --set hidden=[8] --set batch=0 -o {O}/m",
        "hyper-parameter batch=0 of model 'cvae' must be a positive integer (default 256)"),
    cli("train-hidden-negative", "train {I}/data.npz --model cvae --epochs 1 --set hidden=[-5] -o {O}/m",
        "hyper-parameter hidden=[-5] of model 'cvae' must be a non-empty list of positive integers"),
    cli("train-config-nested-table",
        "train {I}/data.npz --model cvae --epochs 1 --set hidden=[8] --config {I}/cfg-nested.toml -o {O}/m",
        "unknown cvae model setting 'cvae'; known: batch, beta, encoder_hidden, epochs, hidden, latent, lr, lr_schedule"),
    cli("train-output-folder-of-dataset", "train {O}/data.npz --model cvae --epochs 1 --set hidden=[8] -o {O}",
        "holds data.npz but no model.json nor checkpoint.safetensors, so it is not a model directory; train into a "
        "new or empty folder (-o)"),
    cli("train-output-link-to-other-model",
        "train {I}/data.npz --model cvae --epochs 1 --set hidden=[8] --seed 1 -o {O}/m",
        "{O}/m holds a finished model made with other settings (seed: 0 then, 1 now); choose another directory (-o), "
        "or delete it to train anew"),
    cli("train-dataset-truncated", "train {I}/d-trunc.npz --model cvae --epochs 1 --set hidden=[8] -o {O}/m",
        "{I}/d-trunc.npz is not a readable .npz file (BadZipFile: File is not a zip file); it may be truncated or "
        "another kind of file: regenerate it"),
    cli("train-dataset-zero-rows", "train {I}/d-zero-rows.npz --model cvae --epochs 1 --set hidden=[8] -o {O}/m",
        "dataset has only 0 rows; a model needs at least 10"),
    cli("train-dataset-y-off-its-conditions", "train {I}/d-y-off.npz --model cvae --epochs 1 --set hidden=[8] -o {O}/m",
        "{I}/d-y-off.npz: meta 'per_condition' 5 but 30 rows at condition [5.0]; the file was edited: collect it "
        "again"),
    cli("train-resume-other-seed", RESUME + " --seed 1 -o {O}/m",
        "the checkpoint in {O}/m was made with another dataset, model, seed or settings (seed: 0 then, 1 now); resume "
        "with the same command, or choose another directory"),
    cli("train-resume-other-hidden", RESUME.replace("hidden=[8]", "hidden=[16]") + " -o {O}/m",
        "the checkpoint in {O}/m was made with another dataset, model, seed or settings (config.hidden: [8] then, [16] "
        "now); resume with the same command, or choose another directory"),
    cli("train-resume-other-dataset", RESUME.replace("data.npz", "d-offmanifold.npz") + " -o {O}/m",
        "5 of 30 rows checked fail: recollect the dataset"),
    cli("train-resume-nothing-there", "train {I}/data.npz --model cvae --epochs 1 --set hidden=[8] --resume -o {O}/new",
        "no checkpoint in {O}/new to resume (training finished or never started); run without --resume"),
    cli("train-model-missing-module", "train {I}/data.npz --model nope_mod:X --epochs 1 -o {O}/m",
        "cannot import module 'nope_mod' for model 'nope_mod:X' (No module named 'nope_mod'); put it on PYTHONPATH"),
    cli("train-model-stdlib-class", "train {I}/data.npz --model json:JSONDecoder --epochs 1 -o {O}/m",
        "'json:JSONDecoder' is not a ConditionalSampler subclass; a model class must subclass manifoldgen's "
        "ConditionalSampler"),
    cli("train-two-writers", "train {I}/data.npz --model cvae --epochs 1 --set hidden=[8] -o {O}/m",
        "(lock {O}/m.lock); wait for it to finish or choose another output"),
    cli("train-dataset-fifo", "train {O}/d.npz --model cvae --epochs 1 --set hidden=[8] -o {O}/m",
        "dataset {O}/d.npz is not a regular file (a device, pipe or socket)"),
    cli("train-dataset-link-dev-zero", "train {O}/d.npz --model cvae --epochs 1 --set hidden=[8] -o {O}/m",
        "dataset {O}/d.npz is not a regular file (a device, pipe or socket)"),
    cli("sample-n-zero", "sample {I}/model --condition 0.45 -n 0 -o {O}/s.npz",
        "-n must be a positive number of samples, at most 1,000,000 (memory grows with it), got 0; write larger "
        "sets as several files with different --seed"),
    cli("sample-n-trillion", "sample {I}/model --condition 0.45 -n 1000000000000 -o {O}/s.npz",
        "at most 1,000,000 (memory grows with it), got 1000000000000; write larger sets as several files"),
    cli("sample-model-trunc-weights", "sample {I}/m-trunc-weights --condition 0.45 -n 10 -o {O}/s.npz",
        "{I}/m-trunc-weights/model.safetensors does not match the checksum in model.json; one of the files was "
        "modified or comes from another model"),
    cli("sample-model-noweights", "sample {I}/m-noweights --condition 0.45 -n 10 -o {O}/s.npz",
        "{I}/m-noweights is missing model.safetensors; it is not a complete model directory (retrain, or copy both"),
    cli("sample-model-jsondir", "sample {I}/m-jsondir --condition 0.45 -n 10 -o {O}/s.npz",
        "{I}/m-jsondir is missing model.json; it is not a complete model directory (retrain, or copy both"),
    cli("sample-model-qstd-zero", "sample {I}/m-qstd-zero --condition 0.45 -n 10 -o {O}/s.npz",
        "{I}/m-qstd-zero/model.json: normalisation standard deviations must be positive; the file was edited or is "
        "damaged: restore it or retrain the model"),
    cli("sample-model-refine-neg", "sample {I}/m-refine-neg --condition 0.45 -n 10 -o {O}/s.npz",
        "{I}/m-refine-neg/model.json has an invalid refine -3; retrain or restore it"),
    cli("sample-model-epochs-str", "sample {I}/m-epochs-str --condition 0.45 -n 10 -o {O}/s.npz",
        "config \"epochs\" is \"many\", not a finite number or a list of widths; the file was edited or is damaged"),
    cli("sample-model-mix-neg", "sample {I}/m-mix-neg --condition 0.45 -n 10 -o {O}/s.npz",
        "{I}/m-mix-neg/model.json has an invalid mix -1 (a share in [0, 1]); retrain or restore it"),
    cli("sample-output-in-sys", "sample {I}/model --condition 0.45 -n 10 -o /sys/s.npz",
        "cannot write /sys/s.npz: Permission denied; choose a writable location (nothing was written)"),
    cli("sample-output-link-to-user-file", "sample {I}/model --condition 0.45 -n 10 -o {O}/s.npz",
        "-o {O}/s.npz exists and was not written by manifoldgen; give another name, or delete it to replace it"),
    cli("sample-pretrained-by-name", "sample panda-pose-cvae --condition 0.45 -n 10 -o {O}/s.npz",
        "model directory not found: panda-pose-cvae; give a model directory written by `manifoldgen train`"),
    cli("plan-time-below-range", WALL + " --time 0.0009 -o {O}/p.npz",
        "--time must be from 0.001 to 86400, got 0.0009"),
    cli("plan-set-empty-value", WALL + " --set range= -o {O}/p.npz",
        "rrtconnect planner setting range must be a number (like its default 0.6), got ''"),
    cli("plan-set-no-equals", WALL + " --set range -o {O}/p.npz",
        "--set 'range' is not KEY=VALUE; write e.g. --set range=1"),
    cli("plan-resolution-zero", WALL + " --set resolution=0 -o {O}/p.npz",
        "planner setting resolution must be a number in [0.0001, 10], got 0.0; e.g. resolution=0.05"),
    cli("plan-edges-coarse-negative", WALL + " --set edges=coarse:-3 -o {O}/p.npz",
        "edges must be 'coarse:K' or 'dense:K' with K a whole number from 1 to 1,000,000 (coarse:1: every motion "
        "state checked for collision at once), got 'coarse:-3'; e.g. edges='coarse:3'"),
    cli("plan-config-range-text", WALL + " --config {I}/cfg-range-str.toml -o {O}/p.npz",
        "rrtconnect planner setting range must be a number (like its default 0.6), got 'far'"),
    cli("plan-config-bad-toml", WALL + " --config {I}/cfg-bad.toml -o {O}/p.npz",
        "{I}/cfg-bad.toml: not valid TOML (Invalid value (at line 1, column 9)); fix the file"),
    cli("plan-planner-capitals", WALL + " --planner RRTConnect -o {O}/p.npz",
        "unknown planner 'RRTConnect'; did you mean rrtconnect?"),
    cli("plan-sampler-empty", WALL.split() + ["--sampler", "", "-o", "{O}/p.npz"],
        "unknown sampler ''; give one of: uniform, project, pg:DATASET.npz, or MODEL:DIR"),
    cli("plan-sampler-pg-missing", WALL + " --sampler pg:{O}/none.npz -o {O}/p.npz",
        "dataset not found: {O}/none.npz"),
    cli("plan-sampler-refine-1001", WALL + " --sampler model:{I}/model,refine=1001 -o {O}/p.npz",
        "sampler option refine=1001 in 'model:{I}/model,refine=1001' must be from 0 to 1,000"),
    cli("plan-model-refine-huge", WALL + " --sampler model:{I}/m-refine-huge -o {O}/p.npz",
        "{I}/m-refine-huge/model.json has an invalid refine 1000000000; retrain or restore it"),
    cli("plan-model-qstd-zero", WALL + " --sampler model:{I}/m-qstd-zero -o {O}/p.npz",
        "{I}/m-qstd-zero/model.json: normalisation standard deviations must be positive; the file was edited or is "
        "damaged: restore it or retrain the model"),
    cli("plan-scene-empty-object", WALL + " --scene {I}/scenes/empty-object.json -o {O}/p.npz",
        "{I}/scenes/empty-object.json lacks obstacles, start, goal, condition; a scene needs obstacles, start, goal "
        "and condition"),
    cli("plan-scene-start-in-wall", WALL + " --scene {I}/scenes/start-in-wall.json -o {O}/p.npz",
        "puts panda_hand_tcp at the start target [0.55, 0.25, 0.3]: the nearest of"),
    cli("plan-scene-goal-outside-limits", WALL + " --scene {I}/scenes/goal-outside-limits.json -o {O}/p.npz",
        "goal configuration outside the joint limits: panda_joint1 = 5.0000 not in [-2.8973, 2.8973]; choose a goal "
        "that satisfies the constraint (project it onto the manifold)"),
    cli("plan-scene-cond-far", WALL + " --scene {I}/scenes/cond-far.json -o {O}/p.npz",
        "the condition [5.0] lies outside the task's values (panda_hand_tcp.z in [0.2, 0.7] m): check the scene's "
        "condition"),
    cli("plan-scene-obst-far", WALL + " --scene {I}/scenes/obst-far.json -o {O}/p.npz",
        "pose position [1e+308, 0.0, 0.0] is beyond 1000 m; give metres within that"),
    cli("plan-scene-box-neg", WALL + " --scene {I}/scenes/box-neg.json -o {O}/p.npz",
        "obstacle 'x' size [-0.1, 0.1, 0.1] must be three positive extents in metres"),
    cli("plan-scene-mesh-missing", WALL + " --scene {I}/scenes/mesh-missing.json -o {O}/p.npz",
        "obstacle 'm': mesh file '/nonexistent/x.stl' not found; give the path of an .stl, .obj or .dae file"),
    cli("plan-scene-mesh-npz", WALL + " --scene {I}/scenes/mesh-npz.json -o {O}/p.npz",
        "obstacle 'm': cannot read mesh file {I}/data.npz"),
    cli("plan-scene-fmt-99", WALL + " --scene {I}/scenes/fmt-99.json -o {O}/p.npz",
        "{I}/scenes/fmt-99.json: format_version 99 is not one this version reads (1); write the scene in that format"),
    cli("plan-scene-unknown-key", WALL + " --scene {I}/scenes/unknown-key.json -o {O}/p.npz",
        "{I}/scenes/unknown-key.json: unknown key 'obstacels'; did you mean 'obstacles'?"),
    cli("plan-scene-obst-not-list", WALL + " --scene {I}/scenes/obst-not-list.json -o {O}/p.npz",
        "{I}/scenes/obst-not-list.json: 'obstacles' must be a list"),
    cli("plan-scene-bool-size", WALL + " --scene {I}/scenes/bool-size.json -o {O}/p.npz",
        "obstacle 'wall_left' size (full extents x, y, z) must be 3 numbers, not true/false (True)"),
    cli("plan-scene-scale-zero", WALL + " --scene {I}/scenes/scale-zero.json -o {O}/p.npz",
        "obstacle 'm' scale [0.0, 1.0, 1.0] must be positive"),
    cli("plan-scene-huge-int", WALL + " --scene {I}/scenes/huge-int.json -o {O}/p.npz",
        "{I}/scenes/huge-int.json is not valid JSON (Exceeds the limit (4300 digits) for integer string conversion"),
    cli("plan-scene-type-code", WALL + " --scene {I}/scenes/type-code.json -o {O}/p.npz",
        "obstacle 'm' has unknown type 'evilmod:C'; known types: box, sphere, cylinder, mesh"),
    cli("plan-scene-of-another-task", WALL + " --scene {I}/scenes/pr2-tray-over.json -o {O}/p.npz",
        "scene {I}/scenes/pr2-tray-over.json is for robot 'pr2', not panda; give a scene for panda, or the task for "
        "pr2"),
    cli("plan-scene-fifo", WALL + " --scene {O}/s.json -o {O}/p.npz",
        "scene file {O}/s.json is not a regular file (a device, pipe or socket)"),
    cli("plan-output-over-a-dataset", WALL + " -o {O}/d.npz",
        "-o {O}/d.npz holds a dataset file, which this path file would replace; give another name, or delete it"),
    cli("plan-output-link-to-dataset", WALL + " -o {O}/p.npz",
        "-o {O}/p.npz holds a dataset file, which this path file would replace; give another name, or delete it"),
    cli("plan-roadmap-format-2", WALL + " --roadmap {O}/rm.npz -o {O}/p.npz",
        "{O}/rm.npz: roadmap format 2 is not the one this version reads (1); delete it (the next query starts a new "
        "roadmap)"),
    cli("plan-roadmap-resolution-lie", WALL + " --roadmap {O}/rm.npz -o {O}/p.npz",
        "{O}/rm.npz holds a roadmap for another query: check resolution 0.05 (the file) vs 0.005 (this query); give "
        "this query another roadmap file"),
    cli("plan-roadmap-edge-negative", WALL + " --roadmap {O}/rm.npz -o {O}/p.npz",
        "{O}/rm.npz: 'edges' must join two distinct nodes of the"),
    cli("plan-roadmap-is-a-dataset", WALL + " --roadmap {O}/rm.npz -o {O}/p.npz",
        "{O}/rm.npz is not a roadmap file (its meta says kind None); give a file written by `plan --roadmap`"),
    cli("plan-roadmap-two-writers", WALL + " --roadmap {O}/rm.npz -o {O}/b.npz",
        "(lock {O}/rm.npz.lock); wait for it to finish or choose another output"),
    cli("plan-robot-with-task-file", "plan {I}/tasks/builtin-only.toml --robot pr2 --scene wall --time 10 --no-picture "
        "-o {O}/p.npz", "task file {I}/tasks/builtin-only.toml is for robot 'panda', not 'pr2'; drop --robot (a task "
        "file names its robot) or edit the file's 'robot'"),
    cli("plan-sphere-task-wall", "plan sphere --scene wall --time 10 --no-picture -o {O}/p.npz",
        "unknown scene 'wall' for task sphere on point; named scenes: sphere; or give a path to a scene .json file"),
    cli("view-export-htm-suffix", "view {I}/path.npz --export {O}/v.htm",
        "--export must end in .html, got {O}/v.htm; give a name such as v.html"),
    cli("collect-user-returns-list", "collect {I}/user/u_list.toml --per-condition 5 -o {O}/d.npz",
        "the residual of constraint u_list:Tool is a list, not an array of shape (256, 3)"),  # accepted at first
    cli("view-an-html-page", "view {I}/page.html --export {O}/v.html",
        "cannot show {I}/page.html: unknown file kind '.html'; give a path or dataset/sample .npz, a scene .json, a "
        "task .toml or a built-in task name"),
    cli("view-scene-of-other-task", "view {I}/scenes/pr2-tray-over.json --task pose --export {O}/v.html",
        "scene {I}/scenes/pr2-tray-over.json is for robot 'pr2', not panda; give a scene for panda, or the task for "
        "pr2"),
    cli("view-export-in-sys", "view {I}/path.npz --export /sys/v.html",
        "cannot write /sys/v.html: Permission denied; choose a writable location (nothing was written)"),
    cli("view-path-float32", "view {I}/p-f32.npz --export {O}/v.html",
        "{I}/p-f32.npz: 'path' must be a non-empty (K, n) float64 array of finite numbers (as `plan` writes it), got "
        "float32"),
    cli("traj-acc-scale-two", "trajectory {I}/path.npz --acc-scale 2 -o {O}/t.json",
        "--acc-scale must be in (0, 1], at least 0.001 (a fraction of the robot's limits), got 2.0"),
    cli("traj-dt-zero", "trajectory {I}/path.npz --dt 0 -o {O}/t.json",
        "--dt must be from 0.0001 to 10 seconds, got 0.0"),
    cli("traj-output-over-physics-report", "trajectory {I}/path.npz -o {O}/r.json",
        "-o {O}/r.json holds a physics file, which this trajectory file would replace; give another name, or delete "
        "it to replace it"),
    cli("traj-direct", "trajectory {I}/p-direct.npz -o {O}/t.json",
        "but the path has 2 of length 1.17101; the file was edited: plan the query again"),
    cli("traj-joints-swapped", "trajectory {I}/p-joints-swapped.npz -o {O}/t.json",
        "{I}/p-joints-swapped.npz: its task's home is off its constraint (projecting it moves a joint 0.349); the file "
        "was edited: make it again"),
    cli("traj-time-inf", "trajectory {I}/p-time-inf.npz -o {O}/t.json",
        "{I}/p-time-inf.npz: meta 'time_limit' must be a finite number > 0, got Infinity; the file was edited: plan "
        "the query again"),
    cli("traj-robot-talos", "trajectory {I}/p-robot-talos.npz -o {O}/t.json",
        "{I}/p-robot-talos.npz: meta 'robot' \"talos\" is not its task's robot 'panda'; the file was edited"),
    cli("traj-output-link-to-user-file", "trajectory {I}/path.npz -o {O}/t.json",
        "-o {O}/t.json exists and was not written by manifoldgen; give another name, or delete it to replace it"),
    cli("physics-feet-unknown", "physics {I}/bal.npz --feet nope",
        "unknown frame 'nope' for robot centauro, given as a foot; the balance constraint's feet are contact_1, "
        "contact_2, contact_3, contact_4"),
    cli("physics-tilt-nan", "physics {I}/bal.npz --tilt nan",
        "--tilt must be from 0.1 to 45, got nan"),
    cli("physics-feet-empty", ["physics", "{I}/bal.npz", "--feet", ""],
        "unknown frame '' for robot centauro, given as a foot; the balance constraint's feet are contact_1"),
    cli("physics-settle-inf", "physics {I}/bal.npz --settle inf",
        "--settle must be from 0 to 600, got inf"),
    cli("physics-output-over-trajectory", "physics {I}/bal.npz -o {O}/r.json",
        "-o {O}/r.json holds a trajectory file, which this physics file would replace; give another name, or delete "
        "it to replace it"),
    cli("bench-pg-rows-trillion", BENCH + " -m rrtconnect@pg --pg-rows 1000000000000 -o {O}/b",
        "--pg-rows must be from 1 to 10,000,000 dataset rows, got 1000000000000"),
    cli("bench-baseline-unknown", BENCH + " -m rrtconnect@project --baseline nope -o {O}/b",
        "--baseline 'nope' is not one of the method labels ['rrtconnect@project']"),
    cli("bench-label-300-chars-snapshots", BENCH + " -m " + "a" * 300 + "=rrtconnect@project --snapshots -o {O}/b",
        "is 300 characters long; a name becomes a file name: at most 100; name the method LABEL=... with a plain "
        "LABEL"),
    cli("bench-label-newline", BENCH.split() + ["-m", "a\nb=rrtconnect@project", "-o", "{O}/b"],
        "label 'a\\nb' is not a plain name (letters, digits and _ - . @ + = : , only; no '/', no '..', no leading "
        "'.'): it becomes a file name; name the method LABEL=... with a plain LABEL"),
    cli("bench-label-unicode-snapshots",
        BENCH.split() + ["-m", "mé✓=rrtconnect@project", "--snapshots", "-o", "{O}/b"],
        "label 'mé✓' is not a plain name (letters, digits and _ - . @ + = : , only"),
    cli("bench-resume-record-through-wall", "bench plan pose --scene wall --runs 2 --time 5 -m rrtconnect@project "
        "--resume -o {O}/b", "{O}/b/runs.jsonl: run 0 of 'rrtconnect@project' is recorded valid, but its path "
        "rechecks invalid (segment 0: violates the constraint: residual component 1 is 0.0101, 1.01 times its "
        "tolerance 0.01): the record was edited; remove that line to rerun it, or use another folder"),
    cli("bench-resume-other-seed", "bench plan pose --scene wall --runs 2 --time 5 -m rrtconnect@project --resume "
        "-o {O}/b --seed 5", "{O}/b was run with other settings: seed 0, not 5; resume with the same scene, time "
        "limit, seed, task and settings, or choose another folder"),
    cli("bench-rerun-without-resume", "bench plan pose --scene wall --runs 2 --time 5 -m rrtconnect@project -o {O}/b",
        "{O}/b already holds 2 runs; pass --resume to continue them or choose another output folder"),
    cli("bench-sampling-samples-zero", "bench sampling {I}/model --samples 0 --reference 100 --repeats 1 -o {O}/b",
        "--samples must be an integer from 20 to 1,000,000, got 0"),
    cli("bench-sampling-reference-zero", "bench sampling {I}/model --samples 100 --reference 0 --repeats 1 -o {O}/b",
        "--reference must be an integer from 20 to 1,000,000, got 0"),
    cli("bench-sampling-repeats-zero", "bench sampling {I}/model --samples 100 --reference 100 --repeats 0 -o {O}/b",
        "--repeats must be an integer from 1 to 1,000, got 0"),
    cli("bench-sampling-seen-two-values", SAMPLING + " --seen 0.3,0.1 -o {O}/b",
        "condition [0.3, 0.1] has 2 value(s); the task has 1: give 1 comma-separated values"),
    cli("bench-sampling-same-model-twice", SAMPLING.replace("model", "model {I}/model") + " -o {O}/b",
        "a model directory is given twice in ['{I}/model', '{I}/model']; give each once"),
    cli("bench-maze-task-sphere", "bench maze --task sphere --runs 1 --time 2 -o {O}/b",
        "unknown scene 'maze' for task sphere on point; named scenes: sphere; or give a path to a scene .json file"),
    cli("bench-workers-five", BENCH + " -m rrtconnect@project --workers 5 -o {O}/b",
        "--workers must be from 1 to 4 (twice this machine's CPU count), got 5", patch="two_cpus"),
    cli("bench-config-ompl-nan", BENCH + " -m ompl-atlas-rrtconnect --config {I}/cfg-ompl-nan.toml -o {O}/b",
        "planner setting ompl_range must be a finite number, got nan"),
    cli("bench-ompl-native-missing", BENCH + " -m ompl-native-atlas -o {O}/b",
        "the C++ OMPL baseline is not built ({O}/nope missing): apt-get install libompl-dev, then run "
        "benchmarks/ompl_native/build.sh, or set MANIFOLDGEN_OMPL_NATIVE to the program", patch="ompl_native"),
    cli("tasks-type-capital", "tasks {I}/tasks/type-capital.toml",
        "{I}/tasks/type-capital.toml, line 11: constraint 1: unknown constraint 'Pose'; did you mean pose?"),
    cli("tasks-locked-in-group", "tasks {I}/tasks/locked-in-group.toml",
        "joint 'panda_joint1' is in the planning group of robot panda, so it cannot be locked; lock it or plan it, "
        "not both (drop it from 'locked' or from 'group')"),
    cli("tasks-locked-outside", "tasks {I}/tasks/locked-outside.toml",
        "{I}/tasks/locked-outside.toml, line 10: locked joint 'panda_finger_joint1' = 5 is outside its limits [0, "
        "0.04] on robot panda"),
    cli("tasks-group-dup", "tasks {I}/tasks/group-dup.toml",
        "joint 'panda_joint1' is 2 times in the planning group of panda; list it once"),
    cli("tasks-group-empty", "tasks {I}/tasks/group-empty.toml",
        "empty planning group for robot panda; name at least one joint, or leave joints unset for every movable joint"),
    cli("tasks-group-fixed", "tasks {I}/tasks/group-fixed.toml",
        "joint 'panda_hand_joint' of robot panda is fixed and cannot move; remove it from the planning group"),
    cli("tasks-scene-missing", "tasks {I}/tasks/scene-missing.toml",
        "scene 'gone': {I}/tasks/nope.json does not exist (scene paths are relative to the task file's folder); fix "
        "the path or drop the scene"),
    cli("tasks-robot-passwd", "tasks {I}/tasks/robot-passwd.toml",
        "cannot parse URDF /etc/passwd: not well-formed (invalid token): line 1, column 16; check that the file is a "
        "valid URDF"),
    cli("tasks-tol-str", "tasks {I}/tasks/tol-str.toml",
        "line 11: constraint 1: constraint 'pose': orientation_tolerance must be a finite number (written without "
        "quotes), got '0.01'"),
    cli("tasks-tol-bool", "tasks {I}/tasks/tol-bool.toml",
        "line 11: constraint 1: constraint 'pose': position_tolerance must be a finite number, got True"),
    cli("tasks-planner-misspelt", "tasks {I}/tasks/planner-misspelt.toml",
        "{I}/tasks/planner-misspelt.toml, line 10: unknown planner setting 'rnage' (did you mean 'range'?)"),
    cli("tasks-planner-range-neg", "tasks {I}/tasks/planner-range-neg.toml",
        "planner setting range must be a number in [0.0001, 100], got -1.0; e.g. range=0.6"),
    cli("tasks-planner-edges-bad", "tasks {I}/tasks/planner-edges-bad.toml",
        "line 10: edges must be 'coarse:K' or 'dense:K' with K a whole number from 1 to 1,000,000"),
    cli("tasks-dup-key", "tasks {I}/tasks/dup-key.toml",
        "{I}/tasks/dup-key.toml: not valid TOML (Cannot overwrite a value (at line 10, column 23)); fix the file"),
    cli("tasks-axes-w", "tasks {I}/tasks/axes-w.toml",
        "pose position_axes ['w'] must be distinct names among x, y, z"),
    cli("tasks-axes-string", "tasks {I}/tasks/axes-string.toml",
        "position_axes must be a list (e.g. [\"z\"] or [0.0, 0.0, 1.0]), got 'xz'"),
    cli("tasks-values-int-huge", "tasks {I}/tasks/values-int-huge.toml",
        "home_condition [0.45] is outside the task's condition values (panda_hand_tcp.z in [0.5, 9.22337e+18] m); give "
        "a home_condition inside them"),
    cli("tasks-frame-unknown", "tasks {I}/tasks/frame-unknown.toml",
        "unknown frame 'panda_hand_tpc' for robot panda; did you mean panda_hand_tcp"),
    cli("tasks-att-zero", "tasks {I}/tasks/att-zero.toml",
        "obstacle 'cup' size [0.0, 0.0, 0.0] must be three positive extents in metres"),
    cli("tasks-bounds-reversed", "tasks {I}/tasks/bounds-reversed.toml",
        "base_bounds must be [[low], [high]] of x, y, z (and optionally yaw, pitch, roll), low <= high; got [[1.0, "
        "1.0, 1.0], [-1.0, -1.0, -1.0]]"),
    cli("tasks-bounds-nan", "tasks {I}/tasks/bounds-nan.toml",
        "home has 7 values but the group has 13 joints (base_x, base_y, base_z, base_yaw, base_pitch, base_roll, "
        "panda_joint1, panda_joint2, panda_joint3, panda_joint4, panda_joint5, panda_joint6, panda_joint7); give one "
        "value per joint"),
    cli("tasks-stdlib-class", "tasks {I}/tasks/stdlib-class.toml",
        "{I}/tasks/stdlib-class.toml, line 4: constraint 1: 'json:JSONDecoder' is not a Constraint subclass"),
    cli("tasks-one-file-missing", "tasks {I}/tasks/builtin-only.toml {O}/none.toml",
        "task file not found: {O}/none.toml; give a .toml task file or a built-in task name"),
    cli("robots-urdf-external-entity", "robots {I}/tasks/xxe.urdf",
        "cannot parse URDF {I}/tasks/xxe.urdf: reference to external entity in attribute: line 4, column 14; check "
        "that the file is a valid URDF"),
    cli("robots-urdf-missing-mesh", "robots {I}/tasks/missing-mesh.urdf",
        "cannot parse URDF {I}/tasks/missing-mesh.urdf: Mesh package://nowhere/x.stl could not be found."),
    cli("robots-name-dotdot", "robots ../../etc/passwd",
        "URDF file not found: ../../etc/passwd; give an existing path or a robot name", patch="chdir"),
    cli("robots-name-empty", ["robots", ""],
        "the robot name is empty; give a robot name (`manifoldgen robots` lists them) or the path of a .urdf"),
    cli("sweep-epochs-zero", "sweep {I}/data.npz --epochs 0 -o {O}/s",
        "--epochs must be from 1 to 100000, got 0"),
    cli("sweep-output-is-its-dataset", "sweep {O}/d.npz --model cvae --epochs 1 -o {O}/d.npz",
        "-o {O}/d.npz is an existing file, but a folder is meant here; give a folder path"),
    cli("demo-output-is-a-file", "demo -o {O}/x",
        "-o {O}/x is an existing file, but a folder is meant here; give a folder path"),
    cli("demo-output-in-sys", "demo -o /sys/demo",
        "cannot write /sys/demo: Permission denied; choose a writable location (nothing was written)"),
    api("api-load-task-bytes", lambda I, O: mg.load_task(b"pose"),
        "load_task: name_or_file must be a task name or a task .toml file path, got bytes b'pose'"),
    api("api-load-task-robot-with-file", lambda I, O: mg.load_task(f"{I}/tasks/builtin-only.toml", robot="pr2"),
        "task file {I}/tasks/builtin-only.toml is for robot 'panda', not 'pr2'; drop --robot (a task file names its "
        "robot) or edit the file's 'robot'"),
    api("api-collect-conditions-nan", lambda I, O: mg.collect("pose", per_condition=5, conditions=np.array([[np.nan]])),
        "condition values must be finite numbers, got nan"),
    api("api-collect-out-over-a-path", lambda I, O: mg.collect("pose", per_condition=5, out=f"{O}/p.npz"),
        "collect: out {O}/p.npz holds a path file, which this dataset file would replace; give another name, or "
        "delete it to replace it"),
    api("api-train-dataset-mutated-nan",
        lambda I, O: (lambda d: (d.q.__setitem__((0, 0), np.nan), mg.train(d, "cvae", epochs=1, hidden=[8])))(
            Dataset.load(f"{I}/data.npz")),
        "dataset contains NaN or infinite values; recollect it or drop those rows"),
    api("api-train-epochs-zero", lambda I, O: mg.train(f"{I}/data.npz", "cvae", epochs=0, hidden=[8]),
        "train: epochs must be a positive number (None: the model's own), got 0"),
    api("api-train-hyper-misspelt", lambda I, O: mg.train(f"{I}/data.npz", "cvae", epochs=1, hiden=[8]),
        "unknown hyper-parameter(s) ['hiden'] for model 'cvae'; known: batch, beta, encoder_hidden, epochs, hidden"),
    api("api-sampler-batch-zero", lambda I, O: mg.sampler("pose", "wall", "project", batch=0),
        "sampler: batch must be from 1 to 100,000, got 0"),
    api("api-sampler-batch-ten-million", lambda I, O: mg.sampler("pose", "wall", "project", batch=10**7),
        "sampler: batch must be from 1 to 100,000, got 10000000"),
    api("api-sampler-refine-true", lambda I, O: mg.sampler("pose", "wall", "project", refine=True),
        "sampler: refine must be an integer, got bool True"),
    api("api-plan-scene-of-other-task",
        lambda I, O: mg.plan("pose", mg.load_scene("dualarm", "tray-over"), time_limit=5),
        "plan: scene 'tray-over' is for robot pr2, task pose for panda; load the scene for this task: "
        "mg.load_scene(task, name)"),
    api("api-plan-time-limit-true", lambda I, O: mg.plan("pose", "wall", time_limit=True),
        "plan: time_limit must be a number, got bool True"),
    api("api-plan-sampler-of-other-scene",
        lambda I, O: mg.plan("pose", "wall", sampler=mg.sampler("pose", "maze"), time_limit=5),
        "plan: the sampler was made for scene 'maze', whose obstacles or held object are not those of scene 'wall'; "
        "make it with mg.sampler(task, scene, ...) for this scene"),
    api("api-model-sample-n-negative", lambda I, O: mg.load_model(f"{I}/model").sample(np.array([[0.45]]), -1),
        "number of samples must be >= 0, got -1"),
    api("api-model-sample-y-nan", lambda I, O: mg.load_model(f"{I}/model").sample(np.array([[np.nan]]), 3),
        "condition y must be finite numbers of sensible size, got [nan]"),
    api("api-load-scene-dict", lambda I, O: mg.load_scene("pose", {"obstacles": []}),
        "load_scene: name must be a scene name or a scene .json file path, got dict {'obstacles': []}"),
    api("api-set-threads-million", lambda I, O: set_threads(10**6),
        "threads must be a whole number from 1 to 256, got 1000000"),
    api("api-pretrained-unknown", lambda I, O: mg.pretrained_model_dir("nope"),
        "no pretrained model 'nope' (a shipped model's plain name, not a path); shipped: panda-pose-cvae"),
    api("api-load-model-path-file", lambda I, O: mg.load_model(f"{I}/path.npz"),
        "model directory {I}/path.npz is a file, not a directory; give a model directory written by `manifoldgen "
        "train`"),
]


def _linked(name: str, target: str, source: str | None = None):
    """A set-up: ``name`` a symbolic link to ``target``, a copy of the input ``source`` or else a user's text."""
    def setup(I, O):
        if source:
            copied(source, target)(I, O)
        else:
            (O / target).write_text("keep\n")
        (O / name).symlink_to(O / target)
    return setup


def _held(name: str):
    """A set-up: a writer of ``name`` still running, its lock held (flock, as the commands take it) by this process
    until the case ends; returns the open lock file."""
    def setup(I, O):
        lock = open(O / f"{name}.lock", "w")
        lock.write(f"{os.getpid()}\n")
        lock.flush()
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return lock
    return setup


SETUPS = {
    "collect-output-is-dir": lambda I, O: (O / "d.npz").mkdir(),
    "collect-lock-is-a-dir": lambda I, O: (O / "d.npz.lock").mkdir(),
    "collect-two-writers": _held("a.npz"),
    "collect-task-fifo": lambda I, O: os.mkfifo(O / "t.toml"),
    "train-output-folder-of-dataset": copied("data.npz", "data.npz"),
    "train-output-link-to-other-model": _linked("m", "other", "model"),
    "train-resume-other-seed": copied("ck", "m"),
    "train-resume-other-hidden": copied("ck", "m"),
    "train-resume-other-dataset": copied("ck", "m"),
    "train-two-writers": _held("m"),
    "train-dataset-fifo": lambda I, O: os.mkfifo(O / "d.npz"),
    "train-dataset-link-dev-zero": lambda I, O: (O / "d.npz").symlink_to("/dev/zero"),
    "sample-output-link-to-user-file": _linked("s.npz", "mine.txt"),
    "plan-scene-fifo": lambda I, O: os.mkfifo(O / "s.json"),
    "plan-output-over-a-dataset": copied("data.npz", "d.npz"),
    "plan-output-link-to-dataset": _linked("p.npz", "keep.npz", "data.npz"),
    "plan-roadmap-format-2": copied("rm-fmt2.npz", "rm.npz"),
    "plan-roadmap-resolution-lie": copied("rm-res-lie.npz", "rm.npz"),
    "plan-roadmap-edge-negative": copied("rm-edge-neg.npz", "rm.npz"),
    "plan-roadmap-is-a-dataset": copied("data.npz", "rm.npz"),
    "plan-roadmap-two-writers": _held("rm.npz"),
    "traj-output-over-physics-report": copied("phys.json", "r.json"),
    "traj-output-link-to-user-file": _linked("t.json", "mine.txt"),
    "physics-output-over-trajectory": copied("traj.json", "r.json"),
    "bench-resume-record-through-wall": copied("b-rec-direct", "b"),
    "bench-resume-other-seed": copied("bench", "b"),
    "bench-rerun-without-resume": copied("bench", "b"),
    "sweep-output-is-its-dataset": copied("data.npz", "d.npz"),
    "demo-output-is-a-file": copied("data.npz", "x"),
    "api-collect-out-over-a-path": copied("path.npz", "p.npz"),
}
PATCHES = {
    "two_cpus": lambda monkeypatch, O: monkeypatch.setattr(os, "cpu_count", lambda: 2),
    "ompl_native": lambda monkeypatch, O: monkeypatch.setenv("MANIFOLDGEN_OMPL_NATIVE", str(O / "nope")),
    "chdir": lambda monkeypatch, O: monkeypatch.chdir(O),
}


def test_the_table_holds_each_case_once():
    ids = [c.id for c in CASES]
    assert len(set(ids)) == len(ids) == 174 and set(SETUPS) <= set(ids)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_round6_refused_in_one_line(case, inputs, tmp_path, monkeypatch):
    if case.patch:
        PATCHES[case.patch](monkeypatch, tmp_path)
    with within(60):
        refused_after(case, inputs, tmp_path, SETUPS.get(case.id))


def _method(O) -> str:
    return json.loads((O / "b" / "runs.jsonl").read_text().splitlines()[0])["method"]


def _names(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


ACCEPTED = [  # (id, run(I, O), check(I, O, what run returned))
    ("collect-output-unicode", ran(["collect", "pose", "--per-condition", "5", "-o", "{O}/données ✓.npz"]),
     lambda I, O, out: "données ✓.npz: 30 rows" in out and _names(O) == ["données ✓.npz"]),
    ("collect-stale-lock-dead-pid", ran("collect pose --per-condition 5 -o {O}/d.npz",
                                        lambda I, O: (O / "d.npz.lock").write_text("999999\n")),
     lambda I, O, out: _names(O) == ["d.npz"]),
    ("collect-user-prints", ran("collect {I}/user/u_print.toml --per-condition 5 -o {O}/d.npz"),
     lambda I, O, out: "residual called" in out and "15 rows x 7 joints (xarm7, u_print task)" in out),
    ("collect-user-returns-int", ran("collect {I}/user/u_int.toml --per-condition 5 -o {O}/d.npz"),
     lambda I, O, out: "runs through Python callbacks instead" in out and "15 rows" in out),
    ("plan-roadmap-edge-through-wall",
     ran(WALL + " --roadmap {O}/rm.npz -o {O}/p.npz", copied("rm-direct-edge.npz", "rm.npz")),
     lambda I, O, out: "1 edges read from it that failed the check" in out
     and mg.check_path("pose", "wall", mg.QueryResult.load(O / "p.npz")).valid),
    ("view-task-file-export", ran("view {I}/tasks/builtin-only.toml --export {O}/v.html"),
     lambda I, O, out: _names(O) == ["v.html"]),
    ("traj-output-unicode-csv", ran(["trajectory", "{I}/path.npz", "-o", "{O}/trajectoire ✓.csv"]),
     lambda I, O, out: "100.0% valid" in out and _names(O) == ["trajectoire ✓.csv"]),
    ("bench-label-empty", ran(BENCH + " -m =rrtconnect@project -o {O}/b"),
     lambda I, O, out: _method(O) == "rrtconnect@project"),
    ("bench-resume-empty-jsonl",
     ran("bench plan pose --scene wall --runs 2 --time 5 -m rrtconnect@project --resume -o {O}/b",
         copied("b-empty-jsonl", "b")),
     lambda I, O, out: len((O / "b" / "runs.jsonl").read_text().splitlines()) == 2),
    ("bench-method-pg-dataset-file", ran(BENCH + " -m rrtconnect@pg:{I}/data.npz -o {O}/b"),
     lambda I, O, out: _method(O) == "rrtconnect@pg:data.npz"),
    ("tasks-name-unicode", ran("tasks {I}/tasks/name-unicode.toml"),
     lambda I, O, out: "pösé ✓ 名前 panda" in out),
    ("robots-urdf-velocity-zero", ran("robots {I}/tasks/vel-zero.urdf"),
     lambda I, O, out: "frames: base, j1, l1, j2, l2" in out),
    ("sweep-seed-twice", ran("sweep {I}/data.npz --epochs 1 --model cvae --seed 0 --seed 0 -o {O}/s"),
     lambda I, O, out: _names(O / "s" / "candidates") == ["cvae-seed0"]),
    ("api-load-task-pathlib", lambda I, O: mg.load_task(I / "tasks" / "builtin-only.toml").name,
     lambda I, O, name: name == "pose"),
    ("api-collect-per-condition-numpy-int", lambda I, O: mg.collect("pose", per_condition=np.int64(5), anchors=False),
     lambda I, O, data: data.q.shape == (30, 7)),
    ("api-check-path-six-columns", lambda I, O: mg.check_path("pose", "wall", np.zeros((3, 6))),
     lambda I, O, r: not r.valid and r.reason == "path must have shape (K, 7) with K >= 1, got (3, 6)"),
    ("api-check-path-no-waypoints", lambda I, O: mg.check_path("pose", "wall", np.zeros((0, 7))),
     lambda I, O, r: not r.valid and r.reason == "path must have shape (K, 7) with K >= 1, got (0, 7)"),
]


@pytest.mark.parametrize("run, check", [pytest.param(r, c, id=i) for i, r, c in ACCEPTED])
def test_round6_accepted(run, check, inputs, tmp_path):
    got = run(inputs, tmp_path)
    assert check(inputs, tmp_path, got), got
