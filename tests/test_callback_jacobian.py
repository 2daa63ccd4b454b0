"""The Jacobian the compiled core gets from a Python constraint without an analytic one: central differences of
its numpy residual, checked against torch autograd (the Python search's Jacobian) on random rows; autograd kept
for large batches and for a residual whose differences disagree; projections through the core converging to the
Python projection's states."""

from pathlib import Path

import numpy as np
import pytest

from manifoldgen import constraint_callbacks, native
from manifoldgen.constraints import Condition, Constraint
from manifoldgen.space import ConstrainedSpace

USER_TASK = Path(__file__).resolve().parent.parent / "examples" / "user_task" / "tool-down-xarm7.toml"


@pytest.fixture(scope="module")
def task():
    from manifoldgen.tasks import get_task
    return get_task(str(USER_TASK))


class Float32Height(Constraint):
    """A residual computed in float32 (the frame's height minus y): its central differences are noise."""

    def __init__(self, robot, frame):
        self.robot, self.frame = robot, frame
        self.condition = Condition(("z",), ("m",), np.array([[0.3]]))
        self.tolerance = np.full(1, 0.01)

    def residual(self, q, y):
        q, y = self.batch(q, y)
        p = self.robot.frame_pose(q, self.frame)[0]
        return (p[:, 2:] - y).astype(np.float32) if isinstance(p, np.ndarray) else p[:, 2:] - y


def _autograd_calls(part, monkeypatch) -> list:
    """Record the rows of every call to ``part``'s (autograd) jacobian (for the test's duration)."""
    calls, jacobian = [], part.jacobian

    def counted(q, y):
        calls.append(len(q))
        return jacobian(q, y)
    monkeypatch.setattr(part, "jacobian", counted, raising=False)
    return calls


def test_central_differences_equal_autograd_on_random_rows(task):
    c, rng = task.constraint, np.random.default_rng(0)
    for B in (1, 7, 200):
        q = task.robot.sample_uniform(B, rng)
        y = rng.uniform(0.3, 0.5, (B, 1))
        F, J = constraint_callbacks.central_difference(c.residual, q, y)
        F_ref, J_ref = c.jacobian(q, y)
        assert F.shape == (B, 3) and J.shape == (B, 3, 7)
        np.testing.assert_allclose(F, c.residual(q, y), rtol=0, atol=1e-15)
        np.testing.assert_allclose(F, F_ref, rtol=0, atol=1e-12)
        np.testing.assert_allclose(J, J_ref, rtol=0, atol=1e-9)  # entries are O(1): metres and unit vectors
        assert np.abs(J_ref).max() > 0.5
    F, J = constraint_callbacks.central_difference(lambda q, y: q[:, :0], q, y)  # a part with inequalities only
    assert F.shape == (200, 0) and J.shape == (200, 0, 7)


def test_callback_takes_differences_on_small_batches_and_autograd_on_large_ones(task, monkeypatch):
    part = task.constraint
    calls = _autograd_calls(part, monkeypatch)
    callback = constraint_callbacks.ConstraintCallback([(part, np.array([0.4]))])
    rng = np.random.default_rng(1)
    small = task.robot.sample_uniform(3, rng)
    for _ in range(4):
        F, J = callback.residuals(small, True)
    assert calls == [3]  # one autograd call only: the first call's check against it
    F_ref, J_ref = part.jacobian(small, np.full((3, 1), 0.4))
    np.testing.assert_allclose(J, J_ref, rtol=0, atol=1e-9)
    assert F.flags.c_contiguous and J.flags.c_contiguous and F.dtype == J.dtype == np.float64
    large = task.robot.sample_uniform(constraint_callbacks.FD_ROWS // 15 + 1, rng)  # (2n + 1) B > FD_ROWS
    calls.clear()
    F, J = callback.residuals(large, True)
    assert calls == [len(large)]
    np.testing.assert_array_equal(J, part.jacobian(large, np.full((len(large), 1), 0.4))[1])


def test_analytic_jacobian_is_used_as_is(task):
    from manifoldgen.constraints.plane import PlaneConstraint
    plane = PlaneConstraint(task.robot, "link_eef", [[1.0, 0.0, 0.0]], [[0.4]])
    q = task.robot.sample_uniform(2, np.random.default_rng(2))
    F, J = constraint_callbacks.ConstraintCallback([(plane, np.array([0.4]))]).residuals(q, True)
    F_ref, J_ref = plane.jacobian(q, np.full((2, 1), 0.4))
    np.testing.assert_array_equal(F, F_ref)
    np.testing.assert_array_equal(J, J_ref)


def test_a_residual_whose_differences_disagree_keeps_autograd_and_says_so(task, monkeypatch):
    part = Float32Height(task.robot, "link_eef")
    callback = constraint_callbacks.ConstraintCallback([(part, np.array([0.3]))])
    q = task.robot.sample_uniform(4, np.random.default_rng(3))
    with pytest.warns(UserWarning, match="central differences of its numpy residual differ"):
        _, J = callback.residuals(q, True)
    calls = _autograd_calls(part, monkeypatch)
    _, J = callback.residuals(q, True)
    assert calls == [4]
    np.testing.assert_allclose(J, part.jacobian(q, np.full((4, 1), 0.3))[1], rtol=0, atol=1e-12)


def test_single_row_projections_in_the_core_reach_the_python_states(task, monkeypatch):
    """The core's sequential searches project one row at a time (each iteration one Jacobian call on one row):
    with central differences they take the Python projection's iterations (autograd) to the same states."""
    pytest.importorskip("manifoldgen_core", reason="the compiled core is not built (scripts/setup.sh builds it)")
    space = ConstrainedSpace(task.constraint, [0.4])
    core = native.core_space(space, compile=False)  # the callback path (a residual that does not trace)
    calls = _autograd_calls(task.constraint, monkeypatch)
    q = task.robot.sample_uniform(12, np.random.default_rng(4))
    reference = space.project(q)
    assert reference.converged.sum() >= 6
    calls.clear()
    for i in range(len(q)):
        before = core.counts()["callback_calls"]
        x, ok, iterations, _ = core.project(q[i:i + 1], 1e-6, 50, 1e-6, 0.5)
        assert core.counts()["callback_calls"] - before == iterations[0] + 1  # one call per iteration
        assert bool(ok[0]) == reference.converged[i] and iterations[0] == reference.iterations[i]
        if ok[0]:
            np.testing.assert_allclose(x[0], reference.q[i], rtol=0, atol=1e-9)
            assert space.constraint.violation(x, space.y)[0] <= 1e-4  # |F| <= 1e-6 against tolerance 0.01
    assert calls == [1]  # autograd once: the first call's check (one row); central differences since
