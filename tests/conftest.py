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


def pytest_sessionfinish(session, exitstatus):
    session.config._manifoldgen_status = int(exitstatus)


def pytest_unconfigure(config):
    """End the process once pytest has reported, keeping its exit status.

    OMPL's nanobind bindings print a long, harmless "leaked instances" report during interpreter
    teardown (see DESIGN.md); it would bury pytest's summary line, so teardown is skipped.
    """
    import os
    import sys

    status = getattr(config, "_manifoldgen_status", None)
    if status is not None and "ompl" in sys.modules:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
