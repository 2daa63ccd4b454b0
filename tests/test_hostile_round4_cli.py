"""Refusals of a hostile round through the command line: an SRDF that is a URDF, obstacle keys and values a shape
does not take, an edited path file meta or bench record, an output that would replace a file manifoldgen did not
write, unknown feet; each one line naming the problem and the fix, no input changed."""

from __future__ import annotations

import json
import os
import shutil
import warnings

import numpy as np
import pytest
from typer.testing import CliRunner

from manifoldgen.bench.planning import BENCH_MARKERS
from manifoldgen.cli import _warn_same_pace, app
from manifoldgen.io import GENERATOR_MARK, check_output_path, load_npz, save_npz, written_by_manifoldgen
from manifoldgen.physics import PhysicsSettings
from manifoldgen.query import PATH_FORMAT_VERSION
from manifoldgen.robot import resolve_robot
from manifoldgen.tasks import BUILTIN_DIR, get_task
from refusals import cli, edited_npz, refused_as_told, set_key

runner = CliRunner()
PANDA_URDF = resolve_robot("panda")[0]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, planned_path):
    """Task files (an SRDF that is a URDF, a home_condition outside the values), scenes with a wrong obstacle, edited
    path files, a user's page, .npz and folder, a bench folder with an edited path, a balance path file."""
    root = tmp_path_factory.mktemp("inputs")
    text = (BUILTIN_DIR / "pose-panda.toml").read_text().replace('"scenes/', f'"{BUILTIN_DIR}/scenes/')
    shutil.copy(PANDA_URDF, root / "copy.srdf")
    for name, srdf in (("srdf-urdf", PANDA_URDF), ("srdf-copy", root / "copy.srdf")):
        (root / f"{name}.toml").write_text(text.replace('robot = "panda"', f'robot = "panda"\nsrdf = "{srdf}"'))
    (root / "home-far.toml").write_text(text.replace("home_condition = [0.45]", "home_condition = [5.0]"))
    wall = json.loads((BUILTIN_DIR / "scenes" / "panda-wall.json").read_text())
    for name, change in (("box-radius", {"radius": 0.2}),
                         ("position-str", {"pose": {"position": [0.55, 0.25, "0.3"]}})):
        edited = json.loads(json.dumps(wall))
        edited["obstacles"][0].update(change)
        (root / f"{name}.json").write_text(json.dumps(edited))
    held = {"name": "ball", "type": "sphere", "radius": 0.03, "size": [0.1, 0.1, 0.1], "attached_to": "panda_hand",
            "pose": {"position": [0, 0, 0.1]}}
    (root / "held-size.json").write_text(json.dumps({**wall, "attached": held}))
    path = planned_path("wall")
    shutil.copy(path, root / "path.npz")
    for name, edit in (("names", set_key("condition_names", value=["x"])), ("seed", set_key("seed", value=-1)),
                       ("time", set_key("result", "time_s", value=-3)), ("smoothed", set_key("smoothed", value="yes")),
                       ("limit", set_key("time_limit", value=float("inf"))),
                       ("bogus", set_key("planner_settings", "bogus", value=1)),
                       ("range", set_key("planner_settings", "range", value="abc")),
                       ("extra", set_key("validation", "extra", value=1))):
        edited_npz(path, root / f"pv-{name}.npz", edit)
    (root / "mine.html").write_text("<html><body>my notes</body></html>")
    (root / "mine.png").write_bytes(b"\x89PNG\r\n\x1a\n my picture")
    (root / "mine.json").write_text('{"generator": "me", "notes": 1}')
    (root / "mine.csv").write_text("time_s,x\n0,1\n")
    (root / "picdir").mkdir()
    (root / "picdir" / "p.png").write_bytes(b"\x89PNG\r\n\x1a\n my picture")
    np.savez(root / "mine.npz", x=np.arange(3))
    for folder in ("userdir", "pdir.png", "tdir.json"):
        (root / folder).mkdir()
    (root / "userdir" / "notes.txt").write_text("notes")
    (root / "userdir" / "results.md").write_text("my results")
    (root / "cfgdir").mkdir()
    (root / "cfgdir" / "config.json").write_text('{"mine": 1}')
    os.symlink(root / "loop2.npz", root / "loop1.npz")
    os.symlink(root / "loop1.npz", root / "loop2.npz")
    bench = runner.invoke(app, ["bench", "plan", "pose", "--scene", "wall", "--time", "2", "--runs", "1",
                                "-m", "rrtconnect@project", "-o", str(root / "bench")])
    assert bench.exit_code == 0, bench.output
    record = json.loads((root / "bench" / "runs.jsonl").read_text())
    assert record["valid"], record
    for name, change in (("length", {"length": record["length"] * 0.5}), ("seed", {"seed": 7}),
                         ("solved", {"planner_solved": False})):
        shutil.copytree(root / "bench", root / f"bench-{name}")
        (root / f"bench-{name}" / "runs.jsonl").write_text(json.dumps({**record, **change}) + "\n")
    record["path"][len(record["path"]) // 2][0] += 0.3  # off the manifold, the record still saying valid
    (root / "bench" / "runs.jsonl").write_text(json.dumps(record) + "\n")
    task = get_task("balance", "centauro")
    meta = {**task.meta(), "kind": "path", "format_version": PATH_FORMAT_VERSION, "condition": [0.8]}
    save_npz(root / "balance.npz", meta, path=np.array([task.home, task.home]))
    return root


CASES = [
    # an SRDF must be a .srdf holding SRDF elements, refused when the task is read
    cli("srdf-is-a-urdf", "tasks {I}/srdf-urdf.toml", f"SRDF {PANDA_URDF} must be a .srdf file"),
    cli("srdf-is-a-renamed-urdf", "collect {I}/srdf-copy.toml -o {O}/x.npz",
        "copy.srdf is not an SRDF: it has a top-level <link>, as a URDF does"),
    cli("home-condition-outside", "tasks {I}/home-far.toml",
        "home_condition [5.0] is outside the task's condition values (panda_hand_tcp.z in [0.2, 0.7] m)"),
    # a shape takes only its own keys, and numbers where numbers belong
    cli("box-with-radius", "plan pose --scene {I}/box-radius.json --no-picture -o {O}/p.npz",
        "obstacle 'wall_left' (a box): unknown key 'radius'; known keys: name, type, pose, size"),
    cli("position-string", "plan pose --scene {I}/position-str.json --no-picture -o {O}/p.npz",
        "obstacle 'wall_left' pose position must be 3 numbers, not a string ('0.3')"),
    cli("held-sphere-with-size", "plan pose --scene {I}/held-size.json --no-picture -o {O}/p.npz",
        "obstacle 'ball' (a sphere): unknown key 'size'"),
    # a path file's meta values have their kinds and ranges, its nested objects their keys
    cli("path-condition-names", "trajectory {I}/pv-names.npz -o {O}/t.json",
        "meta 'condition_names' [\"x\"] are not its task's [\"panda_hand_tcp.z\"]"),
    cli("path-seed-negative", "trajectory {I}/pv-seed.npz -o {O}/t.json",
        "meta 'seed' must be a whole number from 0 to 4294967295, got -1"),
    cli("path-time-negative", "trajectory {I}/pv-time.npz -o {O}/t.json",
        "meta 'result.time_s' must be a finite number >= 0, got -3"),
    cli("path-smoothed-string", "trajectory {I}/pv-smoothed.npz -o {O}/t.json",
        "meta 'smoothed' must be true or false, got \"yes\""),
    cli("path-time-limit-infinite", "trajectory {I}/pv-limit.npz -o {O}/t.json",
        "meta 'time_limit' must be a finite number > 0, got Infinity"),
    cli("path-unknown-setting", "trajectory {I}/pv-bogus.npz -o {O}/t.json",
        "meta 'planner_settings.bogus' is not a setting of planner rrtconnect"),
    cli("path-setting-string", "trajectory {I}/pv-range.npz -o {O}/t.json",
        "setting range must be a number (like its default 0.6), got 'abc'"),
    cli("path-validation-key", "trajectory {I}/pv-extra.npz -o {O}/t.json",
        "meta 'validation.extra' is not a key of 'validation'"),
    # an output replaces only a file manifoldgen wrote; a bench folder must be empty or a bench's own
    cli("export-over-a-users-page", "view {I}/path.npz --export {I}/mine.html",
        "--export {I}/mine.html exists and was not written by manifoldgen; give another name, or delete it"),
    cli("plan-picture-over-a-users-png", "plan pose --scene wall -o {I}/picdir/p.npz",
        "-o's picture {I}/picdir/p.png exists and was not written by manifoldgen"),
    cli("snapshots-over-a-users-png", "view {I}/path.npz --snapshots {I}/mine.png",
        "--snapshots {I}/mine.png exists and was not written by manifoldgen"),
    cli("trajectory-over-a-users-json", "trajectory {I}/path.npz -o {I}/mine.json",
        "-o {I}/mine.json exists and was not written by manifoldgen"),
    cli("trajectory-over-a-users-csv", "trajectory {I}/path.npz -o {I}/mine.csv",
        "-o {I}/mine.csv exists and was not written by manifoldgen"),
    cli("plan-over-a-users-npz", "plan pose --scene wall --no-picture -o {I}/mine.npz",
        "-o {I}/mine.npz exists and was not written by manifoldgen"),
    cli("bench-into-a-users-folder", "bench plan pose --scene wall --time 1 -m rrtconnect@project -o {I}/userdir",
        "-o {I}/userdir holds files this command did not write (notes.txt, results.md; no config.json or runs.jsonl)"),
    cli("bench-sampling-into-a-users-folder", "bench sampling {I}/model -o {I}/userdir", "no results.json"),
    cli("bench-label-too-long", f"bench plan pose --scene wall -m {'a' * 300}=rrtconnect@project -o {{O}}/b",
        "is 300 characters long; a name becomes a file name: at most 100"),
    cli("bench-sampling-unseen-is-trained", "bench sampling {I}/model --unseen 0.5 -o {O}/b",
        "--unseen [0.5] is a condition a model was trained at"),
    cli("bench-resume-edited-path", "bench plan pose --scene wall --time 2 --runs 2 -m rrtconnect@project --resume "
        "-o {I}/bench", "run 0 of 'rrtconnect@project' is recorded valid, but its path rechecks invalid"),
    cli("bench-over-a-users-config", "bench plan pose --scene wall --time 1 -m rrtconnect@project -o {I}/cfgdir",
        "config.json is not a config bench wrote (damaged, or someone else's); move or delete it"),
    cli("bench-resume-edited-length", "bench plan pose --scene wall --time 2 --runs 2 -m rrtconnect@project "
        "--resume -o {I}/bench-length", "but its path has"),
    cli("bench-resume-edited-seed", "bench plan pose --scene wall --time 2 --runs 2 -m rrtconnect@project "
        "--resume -o {I}/bench-seed", "run 0 of 'rrtconnect@project' has seed 7 where its run gives 0"),
    cli("bench-resume-solved-unsolved", "bench plan pose --scene wall --time 2 --runs 2 -m rrtconnect@project "
        "--resume -o {I}/bench-solved", "has solved true where its run gives false"),
    # a name that is only a suffix, a folder where a file is meant: the fix names what to give
    cli("collect-bare-suffix", "collect pose -o {O}/.npz",
        "-o {O}/.npz is only a suffix, not a file name; give a name such as out.npz"),
    cli("plan-picture-is-a-folder", "plan pose --scene wall -o {I}/pdir.npz",
        "the path's picture {I}/pdir.png (the .png beside -o {I}/pdir.npz) is a folder; give -o another name, or "
        "pass --no-picture"),
    cli("trajectory-output-is-a-folder", "trajectory {I}/path.npz -o {I}/tdir.json",
        "give a file path such as {I}/tdir.json/out.json"),
    cli("view-symlink-loop", "view {I}/loop1.npz", "{I}/loop1.npz is a symbolic link loop"),
    # physics: feet the robot has, each once
    cli("physics-unknown-foot", "physics {I}/balance.npz --feet nofoot",
        "unknown frame 'nofoot' for robot centauro, given as a foot; the balance constraint's feet are "
        "contact_1, contact_2, contact_3, contact_4"),
    cli("physics-near-foot", "physics {I}/balance.npz --feet contact_5", "did you mean contact_4"),
    cli("physics-foot-twice", "physics {I}/balance.npz --feet contact_1 --feet contact_1",
        "foot frame 'contact_1' is given twice"),
    cli("robot-in-capitals", "robots PANDA", "unknown robot 'PANDA' (did you mean panda?)"),
    cli("time-just-over-a-day", "plan pose --scene wall --time 86400.001 -o {O}/p.npz",
        "--time must be from 0.001 to 86400, got 86400.001"),
    cli("tasks-given-a-json", f"tasks {BUILTIN_DIR}/scenes/panda-wall.json", "a .json file is not a task file"),
]


@pytest.fixture(scope="module")
def with_model(inputs, tmp_path_factory):
    """The inputs with a tiny model (for bench sampling)."""
    from manifoldgen.data import collect
    from manifoldgen.models import CVAE

    data = collect(get_task("pose", "panda"), 12, seed=0, conditions=[[0.3], [0.5]], progress=False)
    CVAE(hidden=[8], batch=8, epochs=1, patience=5).fit(data, seed=0, progress=False, out=inputs / "model")
    return inputs


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_refused_in_one_line(case, with_model, tmp_path):
    refused_as_told(case, with_model, tmp_path)


def test_a_home_condition_outside_is_one_line_without_a_warning(inputs):
    result = runner.invoke(app, ["tasks", str(inputs / "home-far.toml")])
    assert result.exit_code == 2 and result.stderr.count("\n") == 1 and "warning" not in result.stderr, result.stderr


def test_an_exported_page_carries_the_mark_and_may_be_exported_again(inputs, tmp_path):
    page = tmp_path / "p.html"
    for _ in range(2):
        result = runner.invoke(app, ["view", str(inputs / "path.npz"), "--export", str(page)])
        assert result.exit_code == 0, result.output
    assert GENERATOR_MARK in page.read_text()[:4096]


def test_pictures_trajectories_and_reports_carry_the_mark_and_may_be_written_again(inputs, tmp_path):
    """A .png, .json or .csv manifoldgen wrote is its own: the same command replaces it (a user's is refused)."""
    commands = [["plan", "pose", "--scene", "wall", "--time", "2", "-o", str(tmp_path / "p.npz")],
                ["view", str(inputs / "path.npz"), "--snapshots", str(tmp_path / "s.png")],
                ["trajectory", str(inputs / "path.npz"), "-o", str(tmp_path / "t.json")],
                ["trajectory", str(inputs / "path.npz"), "-o", str(tmp_path / "t.csv")]]
    for command in commands:
        for _ in range(2):
            result = runner.invoke(app, command)
            assert result.exit_code == 0, result.output
    for name in ("p.png", "s.png", "t.json", "t.csv"):
        assert written_by_manifoldgen(tmp_path / name), name


def test_an_empty_folder_or_a_benchs_own_takes_a_bench(tmp_path):
    (tmp_path / "empty").mkdir()
    assert check_output_path(tmp_path / "empty", directory=True, markers=BENCH_MARKERS) == tmp_path / "empty"
    for marker in BENCH_MARKERS:  # runs.jsonl alone: a folder whose damaged config.json was deleted, as told
        own = tmp_path / marker.replace(".", "-")
        own.mkdir()
        (own / marker).write_text("")
        (own / "results.md").write_text("")
        assert check_output_path(own, directory=True, markers=BENCH_MARKERS) == own


def test_duration_scale_says_what_it_does_and_warns_where_it_changes_nothing(inputs, tmp_path):
    help_text = " ".join(runner.invoke(app, ["physics", "--help"], terminal_width=400).output.split())
    assert "Divides the speed limits" in help_text and "acceleration limits" in help_text
    task = get_task("balance", "centauro")
    meta = load_npz(inputs / "balance.npz", ())[0]
    slow = PhysicsSettings(seconds_per_rad=1.0, seconds_per_m=5.0)
    small, large = task.home.copy(), task.home.copy()
    small[-1] += 0.01  # a step its acceleration limit paces
    large[-1] += 1.0  # a step its speed limit paces
    save_npz(tmp_path / "small.npz", meta, path=np.array([task.home, small]))
    with pytest.warns(UserWarning, match="--duration-scale 0.5 changes nothing for this path"):
        _warn_same_pace(tmp_path / "small.npz", slow, PhysicsSettings(), 0.5)
    save_npz(tmp_path / "large.npz", meta, path=np.array([task.home, large]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _warn_same_pace(tmp_path / "large.npz", slow, PhysicsSettings(), 0.5)
