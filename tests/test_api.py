"""The Python API (``import manifoldgen as mg``): the README's quick start runs as written, every exported name
resolves, importing the package stays cheap, one schema for solved and unsolved queries, one error type for
wrong argument types."""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import manifoldgen as mg

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PRETRAINED = ROOT / "src" / "manifoldgen" / "data" / "pretrained" / "panda-pose-cvae"


def readme_python_blocks() -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", README.read_text(encoding="utf-8"), flags=re.S | re.M)


@pytest.fixture(scope="module")
def wall():
    task = mg.load_task("pose", robot="panda")
    return task, mg.load_scene(task, "wall")


def test_the_readme_quick_start_runs_and_plans_a_valid_path(tmp_path, monkeypatch, capsys):
    blocks = readme_python_blocks()
    assert len(blocks) == 1, "the README has one ```python block: the quick start"
    code = blocks[0]
    assert 5 <= len(code.strip().splitlines()) <= 14, "the quick start stays about 10 lines"
    monkeypatch.chdir(tmp_path)  # it writes its path file into the working folder
    scope: dict = {}
    exec(compile(code, str(README), "exec"), scope)
    result, report, task, scene = scope["result"], scope["report"], scope["task"], scope["scene"]
    assert result.solved and result.valid
    path = result.path
    assert path.ndim == 2 and path.shape[1] == task.robot.n and len(path) >= 2
    np.testing.assert_allclose(path[0], scene.start)
    np.testing.assert_allclose(path[-1], scene.goal)
    # the API's check, state by state along every segment (every 0.005 rad): more states than waypoints
    assert report.valid and report.reason == "" and report.segment == -1
    assert report.states_checked > len(path) and report.resolution == 0.005
    assert 0 <= report.worst_violation <= 1
    for waypoint in path:  # and each waypoint on its own, a one-state path
        single = mg.check_path(task, scene, waypoint[None])
        assert single.valid and single.states_checked == 1
    written = list(tmp_path.glob("*.npz"))
    assert len(written) == 1, "the quick start writes one path file"
    with np.load(written[0]) as saved:
        np.testing.assert_array_equal(saved["path"], path)
    assert "valid: True" in capsys.readouterr().out


def test_every_exported_name_resolves():
    assert mg.__all__ == sorted(set(mg.__all__))
    for name in mg.__all__:
        assert getattr(mg, name) is not None, name
        assert name in dir(mg)
    assert issubclass(mg.ManifoldgenError, ValueError)
    with pytest.raises(AttributeError):
        mg.no_such_name  # noqa: B018


def test_the_version_is_the_distribution_s_or_pyproject_s(monkeypatch):
    import importlib.metadata
    import tomllib

    assert isinstance(mg.__version__, str) and mg.__version__
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]

    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", missing)
    assert mg._version() == declared  # a source tree without an installed distribution


def test_importing_the_package_imports_no_heavy_module():
    code = ("import sys, manifoldgen, manifoldgen.api\n"
            "manifoldgen.ManifoldgenError, manifoldgen.__version__, manifoldgen.__all__\n"
            "print(' '.join(m for m in ('torch', 'pinocchio', 'matplotlib', 'coal', 'ompl') "
            "if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          cwd=ROOT, env={"PYTHONPATH": str(ROOT / "src"), "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == []


def test_solved_and_unsolved_queries_have_one_schema(wall):
    task, scene = wall
    solved = mg.plan(task, scene, sampler=f"cvae:{PRETRAINED}", seed=0, time_limit=10)
    unsolved = mg.plan(task, scene, sampler="uniform", seed=0, time_limit=0.2)  # rejection never hits the manifold
    unsolved_object = mg.plan(task, scene, sampler=mg.sampler(task, scene, "uniform"), seed=0, time_limit=0.2)
    assert solved.solved and not unsolved.solved and not unsolved_object.solved
    a, b, c = solved.to_dict(), unsolved.to_dict(), unsolved_object.to_dict()
    assert set(a) == set(b) == set(c)
    for key in ("result", "validation"):
        assert set(a[key]) == set(b[key]) == set(c[key]), key
    assert a["validation"]["valid"] is True
    assert b["validation"]["valid"] is False and c["validation"]["valid"] is False
    assert b["validation"]["states_checked"] == 0 and not unsolved.valid
    assert unsolved.path.shape == (0, task.robot.n)
    assert unsolved.why().startswith("not solved")
    with pytest.raises(mg.ManifoldgenError, match="not solved, so there is no path to write"):
        unsolved.save("never.npz")


def test_a_saved_path_loads_back_as_the_same_result(wall, tmp_path):
    task, scene = wall
    planned = mg.plan(task, scene, sampler=f"cvae:{PRETRAINED}", seed=0, time_limit=10)
    loaded = mg.QueryResult.load(planned.save(tmp_path / "p.npz"))
    np.testing.assert_array_equal(loaded.path, planned.path)
    assert loaded.to_dict() == planned.to_dict() and loaded.valid and loaded.solved
    assert loaded.result.length == pytest.approx(planned.result.length)
    assert mg.check_path(task, scene, loaded).valid
    with pytest.raises(mg.ManifoldgenError, match="QueryResult.load: file must be a file path \\(str or os.PathLike\\), got int 3"):
        mg.QueryResult.load(3)


def test_a_model_object_a_spec_and_a_sampler_plan_alike(wall):
    task, scene = wall
    model = mg.load_model(PRETRAINED)
    by_object = mg.plan(task, scene, sampler=model, seed=3, time_limit=10)
    by_spec = mg.plan(task, scene, sampler=f"cvae:{PRETRAINED}", seed=3, time_limit=10)
    made = mg.sampler(task, scene, model, seed=3)
    by_sampler = mg.plan(task, scene, sampler=made, seed=3, time_limit=10)
    for result in (by_object, by_spec, by_sampler):
        assert result.solved and mg.check_path(task, scene, result).valid
    assert by_object.meta["sampler"].startswith("cvae:")
    np.testing.assert_array_equal(by_object.path, by_spec.path)  # same model, same seed: same path
    q = made.sample_many(5)
    assert q.shape == (5, task.robot.n) and made.space.valid(q).all()


def test_collect_train_and_a_dataset_sampler(tmp_path, wall):
    task, scene = wall
    data = mg.collect("pose", per_condition=40, seed=0, out=tmp_path / "pose.npz")
    assert isinstance(data, mg.Dataset) and len(data) == 40 * len(task.condition.grid)
    assert len(mg.Dataset.load(tmp_path / "pose.npz")) == len(data)
    model = mg.train(tmp_path / "pose.npz", "cvae", seed=0, out=tmp_path / "cvae", epochs=1, hidden=[16])
    assert (tmp_path / "cvae" / "model.json").is_file()
    assert mg.load_model(tmp_path / "cvae").config["hidden"] == [16] == model.config["hidden"]
    pg = mg.sampler(task, scene, data, seed=0)
    assert pg.space.valid(pg.sample_many(3)).all()


@pytest.mark.parametrize("call, words", [
    (lambda t, s: mg.load_task(3), "load_task: name_or_file must be"),
    (lambda t, s: mg.load_task("pose", robot=7), "load_task: robot must be"),
    (lambda t, s: mg.load_scene(t, 5), "load_scene: name must be"),
    (lambda t, s: mg.load_scene(None, "wall"), "load_scene: task must be"),
    (lambda t, s: mg.plan(t, 5), "plan: scene must be"),
    (lambda t, s: mg.plan(t, s, sampler=3.5), "plan: sampler must be"),
    (lambda t, s: mg.plan(t, s, planner=None), "plan: planner must be"),
    (lambda t, s: mg.plan(t, s, seed="0"), "plan: seed must be an integer"),
    (lambda t, s: mg.plan(t, s, seed=-1), "plan: seed must be an integer from 0"),
    (lambda t, s: mg.plan(t, s, time_limit="10"), "plan: time_limit must be a number"),
    (lambda t, s: mg.plan(t, s, time_limit=0), "plan: time_limit must be from 0.001 to 86400 seconds, got 0"),
    (lambda t, s: mg.plan(t, s, settings=["range=1"]), "plan: settings must be"),
    (lambda t, s: mg.plan(t, s, settings={"no_such": 1}), "plan: unknown rrtconnect setting"),
    (lambda t, s: mg.sampler(t), "sampler: give the scene"),
    (lambda t, s: mg.sampler(t, s, object()), "sampler: model must be"),
    (lambda t, s: mg.collect(t, per_condition="10"), "collect: per_condition must be an integer"),
    (lambda t, s: mg.collect(t, 10, out=3), "collect: out must be"),
    (lambda t, s: mg.train(42), "train: dataset must be"),
    (lambda t, s: mg.load_model(None), "load_model: directory must be"),
    (lambda t, s: mg.check_path(t, s, "no path"), "check_path: path must be"),
    (lambda t, s: mg.check_path(t, s, np.zeros((2, 7)), resolution="fine"), "check_path: resolution must be"),
    (lambda t, s: mg.QueryResult(None, {}).save(None), "QueryResult.save: file must be"),
])
def test_wrong_types_give_one_clear_error(call, words, wall):
    with pytest.raises(mg.ManifoldgenError, match=re.escape(words)):
        call(*wall)


@pytest.mark.slow
def test_train_by_default_races_the_candidates_as_the_command_line_does():
    data = mg.collect("sphere", per_condition=300, seed=3)  # under selection.PARALLEL_ROWS: trained in-process
    model = mg.train(data, seed=1, epochs=2)  # no out: the candidates live in a scratch folder
    assert model.name in ("cvae", "cfm") and model.mix in (0.0, 1.0)
    with pytest.raises(mg.ManifoldgenError, match="hyper-parameters .latent. set one model's; name it"):
        mg.train(data, latent=2)
