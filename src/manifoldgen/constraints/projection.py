"""Batched damped least-squares (Levenberg-Marquardt) projection onto F(q, y) = 0.

Each row iterates ``dq = -J^T (J J^T + lambda I)^-1 F`` with ``lambda = |F|^2 + damping``
(Sugihara's choice: Gauss-Newton near the manifold, gradient-like far from it), a
capped step, and clipping to the joint limits. A joint resting on a limit that the step
would push it through is taken out of the step (its Jacobian column zeroed, the step
recomputed), so the other joints do the work instead of the clip undoing it. Only
unconverged rows are updated.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from manifoldgen.constraints.base import Constraint


@dataclass
class Projection:
    """Result of :func:`project` for a batch of B rows."""

    q: np.ndarray  # (B, n) projected configurations (inside the limits)
    converged: np.ndarray  # (B,) bool: max |F| <= tol
    iterations: np.ndarray  # (B,) int: iterations used (max_iters for failures)
    residual: np.ndarray  # (B,) final max |F|


TOL, MAX_ITERS, DAMPING, MAX_STEP = 1e-6, 50, 1e-6, 0.5  # project's defaults (the compiled core is given them)


def project(constraint: Constraint, q: np.ndarray, y: np.ndarray, *, tol: float = TOL,
            max_iters: int = MAX_ITERS, damping: float = DAMPING, max_step: float = MAX_STEP,
            jacobian: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None) -> Projection:
    """Project configurations ``q (B, n)`` onto the manifold of ``y`` ((k,) or (B, k)).

    Converged rows satisfy max_i |F_i| <= tol. Rows stop early once converged. ``jacobian(q, y)`` gives F (B, m)
    and dF/dq (B, m, n) (default: the constraint's own).
    """
    jacobian = constraint.jacobian if jacobian is None else jacobian
    robot = constraint.robot
    q, y = constraint.batch(q, y)
    q = np.clip(q, robot.lower, robot.upper)
    y = np.ascontiguousarray(y)
    B = len(q)
    iterations = np.full(B, max_iters)
    residual = np.full(B, np.inf)
    active = np.arange(B)
    for it in range(max_iters + 1):
        F, J = jacobian(q[active], y[active])
        err = np.max(np.abs(F), axis=1)
        residual[active] = err
        done = err <= tol
        iterations[active[done]] = it
        active, F, J = active[~done], F[~done], J[~done]
        if len(active) == 0 or it == max_iters:
            break
        lam = np.sum(F * F, axis=1) + damping
        dq = _step(J, F, lam)
        qa = q[active]
        blocked = ((qa <= robot.lower + 1e-9) & (dq < 0)) | ((qa >= robot.upper - 1e-9) & (dq > 0))
        rows = blocked.any(axis=1)
        if rows.any():
            dq[rows] = _step(np.where(blocked[rows, None, :], 0.0, J[rows]), F[rows], lam[rows])
        norm = np.linalg.norm(dq, axis=1, keepdims=True)
        dq *= np.minimum(1.0, max_step / np.maximum(norm, 1e-12))
        q[active] = np.clip(q[active] + dq, robot.lower, robot.upper)
    return Projection(q, residual <= tol, iterations, residual)


def _step(J: np.ndarray, F: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Damped least-squares step (B, n) for Jacobians (B, m, n), residuals (B, m), damping (B,)."""
    A = J @ np.transpose(J, (0, 2, 1)) + lam[:, None, None] * np.eye(F.shape[1])
    return -np.einsum("bmn,bm->bn", J, np.linalg.solve(A, F[..., None])[..., 0])
