"""Shared fixtures: robots and tasks are loaded once per session; the user's cache is shared; torch uses one thread
(its spinning worker threads cost 15x the CPU of the tiny models here when the cores are busy). After each test the
process state that tests are known to change is restored (:func:`_isolated`), so a test's result does not depend on
which tests ran before it in the same process (``pytest -n 2`` deals the files out to two processes in an order of
its own)."""

import sys

from manifoldgen.runtime import set_threads

set_threads(1)  # before any test module imports torch

import numpy as np  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _isolated(tmp_path_factory):
    """After each test: torch back at one thread (a command run in-process, such as ``sample``, sets its own
    count, and a thread count changes float sums in the last bits), and the user modules the test imported from
    the tests' temporary folders forgotten (a later task file's module of that name comes from its own folder)."""
    before = set(sys.modules)
    yield
    torch = sys.modules.get("torch")
    if torch is not None and torch.get_num_threads() != 1:
        set_threads(1)
    temporary = str(tmp_path_factory.getbasetemp())
    for name in set(sys.modules) - before:
        if (getattr(sys.modules[name], "__file__", None) or "").startswith(temporary):
            del sys.modules[name]


@pytest.fixture
def private_cache(tmp_path, monkeypatch):
    """A cache folder of the test's own, for tests that count or damage cache files. Every other test shares the
    user's cache (collision matrices and sphere fits, keyed by the robot's content), as the commands do."""
    monkeypatch.setenv("MANIFOLDGEN_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


@pytest.fixture(scope="session")
def panda_task():
    from manifoldgen.tasks import get_task
    return get_task("pose", "panda")


@pytest.fixture
def rng():
    return np.random.default_rng(0)


@pytest.fixture(scope="session")
def planned_path(tmp_path_factory):
    """``planned_path(scene) -> Path``: a path file of the panda pose task's ``scene`` planned once through the
    CLI with the shipped CVAE (seed 0)."""
    from typer.testing import CliRunner

    from manifoldgen.cli import app
    from manifoldgen.models import pretrained_model_dir

    made = {}

    def plan(scene: str):
        if scene not in made:
            out = tmp_path_factory.mktemp("planned") / f"{scene}.npz"
            result = CliRunner().invoke(app, ["plan", "pose", "--robot", "panda", "--scene", scene, "--sampler",
                                              f"cvae:{pretrained_model_dir()}", "--seed", "0", "--time", "60",
                                              "-o", str(out)])
            assert result.exit_code == 0, result.output
            made[scene] = out
        return made[scene]
    return plan


def pytest_addoption(parser):
    parser.addoption("--full", action="store_true", help="run every test, the slow ones too (what .ci/run runs); "
                     "without it, or an explicit -m, the tests marked slow are left out")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--full") or config.getoption("markexpr"):
        return
    slow = [item for item in items if item.get_closest_marker("slow")]
    if slow:
        config.hook.pytest_deselected(items=slow)
        items[:] = [item for item in items if not item.get_closest_marker("slow")]
