"""Refusals of hostile round 5 for edited files: a path file whose meta says what plan never writes (an unsolved path,
no kind, a resolution the checkers refuse, an unknown local planner, top-level copies that contradict its task), a
roadmap with an array, reach or lengths of its own, task files with numbers as strings or booleans, an empty name or
rows of values too wide, a scene naming an obstacle twice, a URDF with reversed limits, a scene shown for another
robot's task. Each is refused in one line naming the problem and the fix, and no input changes; the files the
commands write still read."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.query import read_path_file
from manifoldgen.tasks import BUILTIN_DIR
from refusals import cli, edited_npz, refused_as_told, set_key

runner = CliRunner()
REPO = Path(__file__).resolve().parents[1]
HOME = "home = [0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398]"
INVERTED_URDF = (
    '<robot name="inv2"><link name="base"/><link name="l1"/><link name="l2"/>\n'
    '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>'
    '<limit lower="1.0" upper="-1.0" effort="1" velocity="1"/></joint>\n'
    '<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.5 0 0"/>'
    '<axis xyz="0 0 1"/><limit lower="-2.0" upper="2.0" effort="1" velocity="1"/></joint></robot>\n')


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, planned_path):
    """Edited copies of a planned path file and of a roadmap, edited task files, a scene naming an obstacle twice,
    a URDF with reversed limits and its task, made once."""
    root = tmp_path_factory.mktemp("round5_files")
    path = planned_path("wall")
    for name, edit in (("solved-false", set_key("result", "solved", value=False)),
                       ("kind-missing", lambda m: m.pop("kind")),
                       ("resolution-tiny", set_key("validation", "resolution", value=1e-300)),
                       ("local-unknown", set_key("local", value="zigzag")),
                       ("floating-base-text", set_key("floating_base", value="no")),
                       ("locked-copy", set_key("locked", value={"panda_finger_joint1": 0.5,
                                                                "panda_finger_joint2": 0.0})),
                       ("constraint-copy", set_key("constraint", "rotation",
                                                value=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))):
        edited_npz(path, root / f"pv-{name}.npz", edit)
    result = runner.invoke(app, ["plan", "pose", "--scene", "wall", "--time", "10", "--no-picture", "--roadmap",
                                 str(root / "rm.npz"), "-o", str(root / "p.npz")])
    assert result.exit_code == 0, result.output
    edited_npz(root / "rm.npz", root / "rm-extra.npz", arrays=lambda a: a.update(q=np.zeros((2, 7))))
    edited_npz(root / "rm.npz", root / "rm-reach-text.npz", set_key("reach", value="far"))
    edited_npz(root / "rm.npz", root / "rm-len32.npz",
               arrays=lambda a: a.update(lengths=a["lengths"].astype(np.float32)))
    text = (BUILTIN_DIR / "pose-panda.toml").read_text().replace('"scenes/', f'"{BUILTIN_DIR}/scenes/')
    for name, old, new in (
            ("home-str", HOME, 'home = ["0.0", "-0.785398", "0.0", "-2.35619", "0.0", "1.5707", "0.785398"]'),
            ("home-bool", HOME, "home = [true, false, true, false, true, true, false]"),
            ("homec-str", "home_condition = [0.45]", 'home_condition = ["0.45"]'),
            ("name-empty", 'name = "pose"', 'name = " "'),
            ("values-3col", "values = [[0.2], [0.3], [0.4], [0.5], [0.6], [0.7]]",
             "values = [[0.3, 0.1, 0.1], [0.5, 0.1, 0.1]]")):
        assert old in text, old
        (root / f"{name}.toml").write_text(text.replace(old, new))
    wall = json.loads((BUILTIN_DIR / "scenes" / "panda-wall.json").read_text())
    wall["obstacles"][1]["name"] = wall["obstacles"][0]["name"]
    (root / "dup-names.json").write_text(json.dumps(wall))
    (root / "inv2.urdf").write_text(INVERTED_URDF)
    (root / "inv2.toml").write_text('name = "inv"\nrobot = "inv2.urdf"\n[[constraints]]\ntype = "joint_linear"\n'
                                    'coefficients = [[1.0, 1.0]]\nvalues = [[0.0], [0.5]]\n')
    return root


PLAN = "plan pose --scene wall --time 10 --no-picture -o {O}/p.npz --roadmap"
CASES = [
    cli("path-meta-solved-false", "trajectory {I}/pv-solved-false.npz -o {O}/t.json",
        "meta 'result.solved' must be true (plan writes only solved, checked paths), got false; the file was edited"),
    cli("path-meta-kind-missing", "trajectory {I}/pv-kind-missing.npz -o {O}/t.json",
        "meta 'kind' is missing (plan writes \"path\"); the file was edited: plan the query again"),
    cli("path-meta-resolution-1e-300", "trajectory {I}/pv-resolution-tiny.npz -o {O}/t.json",
        "meta 'validation.resolution' must be a number from 1e-05 to 0.05 (rad), got 1e-300"),
    cli("path-meta-local-unknown", "trajectory {I}/pv-local-unknown.npz -o {O}/t.json",
        "meta 'local' must be a local planner (auto, interpolate, project, direct), got \"zigzag\""),
    cli("path-meta-floating-base-text", "trajectory {I}/pv-floating-base-text.npz -o {O}/t.json",
        "meta 'floating_base' \"no\" contradicts its task's false; the file was edited: plan the query again"),
    cli("path-meta-locked-copy", "trajectory {I}/pv-locked-copy.npz -o {O}/t.json",
        "meta 'locked' contradicts its task (locked.panda_finger_joint1: 0.5 in the file"),
    cli("path-meta-constraint-copy", "view {I}/pv-constraint-copy.npz --export {O}/v.html",
        "meta 'constraint' contradicts its task (constraint.rotation[1]: [0.0, 1.0, 0.0] in the file, "
        "[0.0, -1.0, 0.0] in the task)"),
    cli("roadmap-extra-array", f"{PLAN} {{I}}/rm-extra.npz",
        "rm-extra.npz: unknown array \"q\" (a roadmap file holds only 'nodes', 'edges' and 'lengths')"),
    cli("roadmap-reach-text", f"{PLAN} {{I}}/rm-reach-text.npz",
        "rm-reach-text.npz: meta 'reach' \"far\" must be a finite number > 0 (rad)"),
    cli("roadmap-lengths-float32", f"{PLAN} {{I}}/rm-len32.npz",
        "rm-len32.npz: 'lengths' must be float64 (what Roadmap.save writes), got float32"),
    cli("task-home-strings", "tasks {I}/home-str.toml",
        "home-str.toml, line 8: home must be a flat list of numbers (no strings or booleans), got [\"0.0\""),
    cli("task-home-booleans", "tasks {I}/home-bool.toml",
        "home must be a flat list of numbers (no strings or booleans), got [true, false"),
    cli("task-home-condition-strings", "tasks {I}/homec-str.toml",
        "home_condition must be a flat list of numbers (no strings or booleans), got [\"0.45\"]"),
    cli("task-name-empty", "tasks {I}/name-empty.toml", "name-empty.toml, line 2: 'name' (task name) is empty"),
    cli("task-values-too-wide", "tasks {I}/values-3col.toml",
        "constraint 1: values rows must hold 1 number(s) (panda_hand_tcp.z), got 3"),
    cli("scene-duplicate-obstacle-names", "plan pose --scene {I}/dup-names.json --time 10 --no-picture -o {O}/p.npz",
        "dup-names.json: obstacle name 'wall_left' is given twice; give each obstacle a name of its own"),
    cli("urdf-limits-reversed", "collect {I}/inv2.toml --per-condition 20 -o {O}/d.npz",
        "joint j1 of {I}/inv2.urdf has lower limit 1 above upper -1; fix the URDF"),
    cli("view-scene-of-another-robot",
        f"view {BUILTIN_DIR}/scenes/pr2-wall.json --task pose --export {{O}}/v.html",
        "pr2-wall.json is for robot 'pr2', not panda; give a scene for panda, or the task for pr2"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_refused_in_one_line(case, inputs, tmp_path):
    refused_as_told(case, inputs, tmp_path)


def test_written_path_and_roadmap_files_still_read(inputs, planned_path, tmp_path):
    """A planned path file passes every check; a roadmap plan wrote is routed through again."""
    meta, path, task = read_path_file(planned_path("wall"))
    assert meta["result"]["solved"] and meta["kind"] == "path" and len(path) > 1
    result = runner.invoke(app, ["trajectory", str(planned_path("wall")), "-o", str(tmp_path / "t.json")])
    assert result.exit_code == 0, result.output
    result = runner.invoke(app, [*PLAN.format(O=tmp_path).split(), str(inputs / "rm.npz")])
    assert result.exit_code == 0 and "routed through it" in result.output, result.output


def test_shipped_task_files_and_scenes_still_load(tmp_path):
    """Every built-in and benchmark task file loads (numbers, names, values rows, URDF limits); a pr2 scene is still
    shown without --task (its own task)."""
    files = sorted(map(str, [*BUILTIN_DIR.glob("*.toml"), *(REPO / "benchmarks" / "heldout").glob("*.toml")]))
    result = runner.invoke(app, ["tasks", *files])
    assert result.exit_code == 0, result.output
    assert len(result.stdout.strip().splitlines()) == len(files)
    result = runner.invoke(app, ["view", str(BUILTIN_DIR / "scenes" / "pr2-wall.json"), "--export",
                                 str(tmp_path / "v.html")])
    assert result.exit_code == 0, result.output
