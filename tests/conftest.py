"""Shared fixtures: robots and tasks are loaded once per session; caches go to a temp dir."""

import numpy as np
import pytest


@pytest.fixture(autouse=True, scope="session")
def _isolated_cache(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv("MANIFOLDGEN_CACHE", str(tmp_path_factory.mktemp("cache")))
    yield
    mp.undo()


@pytest.fixture(scope="session")
def panda_task():
    from manifoldgen.tasks import get_task
    return get_task("pose", "panda")


@pytest.fixture
def rng():
    return np.random.default_rng(0)
