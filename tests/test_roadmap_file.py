"""A planner's roadmap saved to a file and read back: the same roadmap and routes, later queries in a fresh process
routed through it (``plan --roadmap``), files for another query or damaged ones refused in one line, outputs never
overwritten, a file written back holding only nodes and edges that passed the check, a link written through, and the
outside checker (examples/check_roadmap.py) rechecking every edge."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning import PLANNERS
from manifoldgen.planning.roadmap import Roadmap
from manifoldgen.sampling import ProjectionSampler
from manifoldgen.scene import get_scene
from manifoldgen.space import ConstrainedSpace, densify
from manifoldgen.tasks import get_task
from planning_problems import corridor_problem

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
from check_roadmap import roadmap_check  # noqa: E402  (the standalone checker users run)

runner = CliRunner()
SPHERE = ["plan", "sphere", "--scene", "sphere", "--no-picture"]  # OMPL's sphere demo: a point, solved in ~0.05 s
# what the corridor roadmaps of the Python tests say they hold for (the IDENTITY keys a query compares)
CORRIDOR = {"joints": ["x", "y", "z"], "condition": [0.0], "scene_name": "corridor", "tolerance": [0.01],
            "resolution": 0.005}


def _corridor_planner(seed: int = 1):
    constraint, y, checker, start, goal = corridor_problem()
    space = ConstrainedSpace(constraint, y, checker)
    planner = PLANNERS.get("rrt")(space, ProjectionSampler(space, seed=seed), seed=seed,
                                  settings=PLANNERS.get("rrt").settings_type(reuse=True))
    return planner, space, start, goal


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A roadmap file of the sphere task's scene, written by `plan --roadmap` (one query, planned)."""
    folder = tmp_path_factory.mktemp("roadmap")
    result = runner.invoke(app, [*SPHERE, "--roadmap", str(folder / "r.npz"), "-o", str(folder / "p.npz")])
    assert result.exit_code == 0, result.output
    assert "roadmap" in result.output and "not routed" in result.output
    return folder / "r.npz"


def test_save_and_load_give_the_same_roadmap_and_route(tmp_path):
    planner, space, start, goal = _corridor_planner()
    assert planner.solve(start, goal, 20.0).solved
    planner.roadmap.save(tmp_path / "r.npz", CORRIDOR)
    again, *_ = _corridor_planner(seed=2)
    again.load_roadmap(tmp_path / "r.npz", CORRIDOR)
    assert np.array_equal(again.roadmap.q, planner.roadmap.q) and again.roadmap.q.dtype == np.float64
    for ours, theirs in zip(again.roadmap.edge_array(), planner.roadmap.edge_array()):
        assert np.array_equal(ours, theirs)
    meta = json.loads(str(np.load(tmp_path / "r.npz")["meta"]))
    assert (meta["kind"], meta["format_version"], meta["reach"]) == ("roadmap", 1, planner.settings.range)
    near_start, near_goal = start + [0.0, 0.05, 0.0], goal + [0.0, -0.05, 0.0]
    first, second = planner.solve(near_start, near_goal, 20.0), again.solve(near_start, near_goal, 20.0)
    assert second.extras["roadmap"]["routed"] and second.iterations == 0 and second.samples_drawn == 0
    assert np.array_equal(first.path, second.path) and space.validate_path(second.path).valid


def test_an_edge_read_from_a_file_is_checked_before_a_route_takes_it(tmp_path):
    """A file's edges are rechecked when first routed: an edge made invalid by moving a node off the plane is
    dropped, and the route found without it is valid state by state."""
    planner, space, start, goal = _corridor_planner()
    assert planner.solve(start, goal, 20.0).solved
    planner.roadmap.save(tmp_path / "r.npz", CORRIDOR)
    arrays = dict(np.load(tmp_path / "r.npz"))
    middle = len(arrays["nodes"]) // 2
    arrays["nodes"][middle, 2] += 0.5  # off the plane z = 0
    edges = arrays["edges"]
    arrays["lengths"] = np.linalg.norm(arrays["nodes"][edges[:, 1]] - arrays["nodes"][edges[:, 0]], axis=1)
    np.savez(tmp_path / "moved.npz", **arrays)
    again, *_ = _corridor_planner()
    again.load_roadmap(tmp_path / "moved.npz", CORRIDOR)
    result = again.solve(start, goal, 20.0)
    assert result.solved and space.valid(densify(result.path, 0.005)[0]).all()
    assert middle not in again.roadmap.edges[middle - 1]  # the path's edge into the moved node: checked, dropped


def test_a_roadmap_for_another_query_is_refused_naming_both_values(tmp_path):
    planner, *_ = _corridor_planner()
    planner.roadmap.save(tmp_path / "r.npz", CORRIDOR)
    with pytest.raises(ManifoldgenError, match=r"condition \[0.0\] \(the file\) vs \[0.5\] \(this query\); scene "
                                               r"\"corridor\" \(the file\) vs \"maze\".*another roadmap file"):
        planner.load_roadmap(tmp_path / "r.npz", {**CORRIDOR, "condition": [0.5], "scene_name": "maze"})
    other = {**CORRIDOR, "condition": [0.5], "scene_name": "maze", "tolerance": [0.5], "resolution": 0.5,
             "joints": ["a", "b", "c"]}  # five differences: the first three named, the others counted
    with pytest.raises(ManifoldgenError) as refused:
        planner.load_roadmap(tmp_path / "r.npz", other)
    assert str(refused.value).count("(the file) vs") == 3 and "(and 2 more)" in str(refused.value)
    assert len(str(refused.value).replace(str(tmp_path / "r.npz"), "")) < 300


def test_plan_in_a_fresh_process_is_routed_through_the_saved_roadmap(saved, tmp_path):
    roadmap = tmp_path / "r.npz"
    roadmap.write_bytes(saved.read_bytes())
    nodes, before = len(np.load(roadmap)["nodes"]), roadmap.read_bytes()
    done = subprocess.run([sys.executable, "-c", "from manifoldgen.cli import app; app()", *SPHERE, "--roadmap",
                           str(roadmap), "-o", str(tmp_path / "p.npz")], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    # the saved roadmap holds this very query's path: its ends are nodes already, nothing is added or rewritten
    assert f"roadmap {roadmap}: routed through it; {nodes} nodes, unchanged" in done.stdout
    assert roadmap.read_bytes() == before
    path = np.load(tmp_path / "p.npz")["path"]
    assert np.all(np.any(path[1:] != path[:-1], axis=1))  # no waypoint repeated
    task = get_task("sphere")
    scene = get_scene(task, "sphere")
    space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
    assert np.allclose(path[0], scene.start) and np.allclose(path[-1], scene.goal)
    assert space.valid(densify(path, space.settings.resolution)[0]).all()


def _plan_sphere(roadmap: Path, out: Path):
    """``plan`` the sphere task's query with ``--roadmap roadmap``, in this process."""
    return runner.invoke(app, [*SPHERE, "--roadmap", str(roadmap), "-o", str(out)])


def _edited(saved: Path, file: Path, edit) -> Path:
    """A copy of the roadmap file ``saved`` at ``file`` after ``edit(arrays)``, its lengths recomputed (consistent)."""
    arrays = dict(np.load(saved))
    edit(arrays)
    edges = arrays["edges"]
    arrays["lengths"] = np.linalg.norm(arrays["nodes"][edges[:, 1]] - arrays["nodes"][edges[:, 0]], axis=1)
    np.savez(file, **arrays)
    return file


def test_a_node_moved_off_the_manifold_is_not_written_back_nor_its_edges(saved, tmp_path):
    """Every edge read from the file is checked before it is written back, not only those a route takes: the moved
    node's edges fail, and the node, left with none, fails as a state; the line says how many were dropped."""
    def move(arrays):
        arrays["nodes"][5] += 0.3
    roadmap = _edited(saved, tmp_path / "moved.npz", move)
    moved = np.load(roadmap)["nodes"][5]
    result = _plan_sphere(roadmap, tmp_path / "p.npz")
    assert result.exit_code == 0 and "dropped 1 nodes and 2 edges read from it that failed the check" in result.output
    assert not np.any(np.all(np.load(roadmap)["nodes"] == moved, axis=1))
    check = roadmap_check(roadmap)
    assert check["status"] == 0 and check["valid"], check["line"]


def test_a_node_with_no_edge_that_fails_the_validity_rule_is_not_written_back(saved, tmp_path):
    def append(arrays):
        arrays["nodes"] = np.concatenate([arrays["nodes"], [[10.0, 10.0, 10.0]]])  # outside the limits, off the sphere
    roadmap = _edited(saved, tmp_path / "lone.npz", append)
    result = _plan_sphere(roadmap, tmp_path / "p.npz")
    assert result.exit_code == 0 and "routed through it" in result.output, result.output
    assert "dropped 1 nodes and 0 edges" in result.output
    nodes = np.load(roadmap)["nodes"]
    assert len(nodes) == len(np.load(saved)["nodes"]) and np.abs(nodes).max() <= 2.0


def test_roadmap_save_checks_what_was_read_and_no_route_took(tmp_path):
    """The library's save: a file's nodes and edges that no route took are checked before it is written."""
    planner, *_ = _corridor_planner()
    planner.roadmap.add(np.array([[-1.0, 0.0, 0.0], [-1.0, 0.1, 0.0], [-1.0, 0.2, 0.0]]))
    planner.roadmap.save(tmp_path / "r.npz", CORRIDOR)

    def edit(arrays):
        arrays["nodes"][1, 2] = 0.5  # off the plane: its two edges fail, then it fails as a state
        arrays["nodes"] = np.concatenate([arrays["nodes"], [[-1.0, 0.3, 0.5]]])  # off the plane, no edge
    _edited(tmp_path / "r.npz", tmp_path / "edited.npz", edit)
    again, *_ = _corridor_planner()
    again.load_roadmap(tmp_path / "edited.npz", CORRIDOR)
    again.roadmap.save(tmp_path / "edited.npz", CORRIDOR)
    assert again.roadmap.dropped == {"nodes": 2, "edges": 2}
    written = np.load(tmp_path / "edited.npz")
    assert np.array_equal(written["nodes"], [[-1.0, 0.0, 0.0], [-1.0, 0.2, 0.0]]) and len(written["edges"]) == 0


def test_a_roadmap_given_as_a_link_is_written_through_it(saved, tmp_path):
    """The link stays a link and the file it names gets the roadmap (a roadmap shared by a link does not fork)."""
    (tmp_path / "shared").mkdir()
    real = _edited(saved, tmp_path / "shared" / "real.npz",
                   lambda arrays: arrays.update(nodes=np.concatenate([arrays["nodes"], [[10.0, 10.0, 10.0]]])))
    link = tmp_path / "link.npz"
    link.symlink_to(real)
    result = _plan_sphere(link, tmp_path / "p.npz")
    assert result.exit_code == 0 and f"roadmap {link}: routed through it" in result.output, result.output
    assert link.is_symlink() and link.resolve() == real
    assert len(np.load(real)["nodes"]) == len(np.load(saved)["nodes"])  # written: without the appended node
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["link.npz", "p.npz", "real.npz"]
    dangling = tmp_path / "dangling.npz"  # a link to a file still to write: made there
    dangling.symlink_to(tmp_path / "shared" / "new.npz")
    assert _plan_sphere(dangling, tmp_path / "p2.npz").exit_code == 0
    assert dangling.is_symlink() and np.load(tmp_path / "shared" / "new.npz")["nodes"].shape[1] == 3


@pytest.mark.parametrize("link", [False, True])
@pytest.mark.parametrize("clash", ["-o", "--scene"])
def test_roadmap_equal_to_an_output_or_input_is_refused_and_nothing_is_overwritten(tmp_path, clash, link):
    """Also when the roadmap is a link to that file."""
    scene = tmp_path / "scene.json"
    scene.write_bytes(Path(get_task("sphere").scenes["sphere"]).read_bytes())
    out = tmp_path / "p.npz"
    out.write_bytes(b"an earlier path")
    same = out if clash == "-o" else scene
    before = same.read_bytes()
    if link:
        (tmp_path / "link.npz").symlink_to(same)
    result = runner.invoke(app, ["plan", "sphere", "--scene", str(scene), "--no-picture", "--roadmap",
                                 str(tmp_path / "link.npz" if link else same), "-o", str(out)])
    assert result.exit_code == 2 and "--roadmap" in result.output and result.output.count("\n") == 1, result.output
    assert same.read_bytes() == before and out.read_bytes() == b"an earlier path"


def test_a_damaged_or_foreign_roadmap_file_is_refused_in_one_line(saved, tmp_path):
    damaged = tmp_path / "damaged.npz"
    damaged.write_bytes(saved.read_bytes()[:300])
    result = runner.invoke(app, [*SPHERE, "--roadmap", str(damaged), "-o", str(tmp_path / "p.npz")])
    assert result.exit_code == 2 and "not a readable .npz" in result.output and result.output.count("\n") == 1
    path = saved.parent / "p.npz"  # a path file is not a roadmap
    result = runner.invoke(app, [*SPHERE, "--roadmap", str(path), "-o", str(tmp_path / "p.npz")])
    assert result.exit_code == 2 and "not a roadmap file" in result.output, result.output
    assert not (tmp_path / "p.npz").exists()
    arrays = dict(np.load(saved))
    arrays["lengths"] = arrays["lengths"] + 0.1
    np.savez(tmp_path / "edited.npz", **arrays)
    with pytest.raises(ManifoldgenError, match="'lengths' are not the distances"):
        Roadmap.load(tmp_path / "edited.npz", lambda segment: True, 0.6)
    arrays = dict(np.load(saved))
    arrays["nodes"] = arrays["nodes"].astype(np.float32)  # narrowed: its lengths would disagree, its type says why
    np.savez(tmp_path / "narrow.npz", **arrays)
    with pytest.raises(ManifoldgenError, match="'nodes' must be finite float64 numbers .* got float32"):
        Roadmap.load(tmp_path / "narrow.npz", lambda segment: True, 0.6)


def test_plan_refuses_the_roadmap_of_another_scene(saved, tmp_path):
    document = json.loads(Path(get_task("sphere").scenes["sphere"]).read_text())
    document["obstacles"] = document["obstacles"][1:]
    (tmp_path / "fewer.json").write_text(json.dumps(document))
    result = runner.invoke(app, ["plan", "sphere", "--scene", str(tmp_path / "fewer.json"), "--no-picture",
                                 "--roadmap", str(saved), "-o", str(tmp_path / "p.npz")])
    assert result.exit_code == 2 and "scene objects (sha256)" in result.output and "(this query)" in result.output
    assert "another roadmap file" in result.output and not (tmp_path / "p.npz").exists()


def test_the_outside_checker_rechecks_every_edge(saved, tmp_path):
    check = roadmap_check(saved)
    assert check["status"] == 0 and check["valid"] and "VALID" in check["line"], check["line"]
    arrays = dict(np.load(saved))
    assert check["states"] >= len(arrays["edges"]) and check["worst"] <= 1.0
    arrays["nodes"][10] *= 1.05  # off the sphere: 5 times its tolerance
    edges = arrays["edges"]
    arrays["lengths"] = np.linalg.norm(arrays["nodes"][edges[:, 1]] - arrays["nodes"][edges[:, 0]], axis=1)
    np.savez(tmp_path / "off.npz", **arrays)
    check = roadmap_check(tmp_path / "off.npz")
    assert check["status"] == 1 and not check["valid"] and "constraint" in check["reason"]
    touching = {e for e, (a, b) in enumerate(edges) if 10 in (a, b)}
    assert set(check["invalid_edges"]) == touching
