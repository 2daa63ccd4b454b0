"""A Python constraint part as the compiled core calls it back, when it is neither built in nor compiles: batched
residuals, and Jacobians from the part's own ``jacobian``, central differences of its numpy residual (small batches)
or torch autograd (large ones)."""

from __future__ import annotations

import warnings

import numpy as np

from manifoldgen.constraints import Constraint, own_jacobian


# The Jacobian of a Python part without an analytic one: central differences of its numpy residual for small
# batches, where torch autograd's per-operation overhead dominates, autograd for large ones (the core's sequential
# searches, a projected walk's steps or a lazily refined sample, ask for single rows); the costs are measured in
# docs/benchmarks.md, "Python constraints in the core" (benchmarks/bench_user_constraint.py --jacobians).
FD_STEP = 3e-6  # central-difference step, times max(1, |q_j|): near eps^(1/3), where truncation and rounding meet
FD_ROWS = 2048  # above (2n + 1) x B residual rows a call, autograd is cheaper (n = 7: B > 136)
FD_AGREE = 1e-6  # first use: central differences must match autograd within this x max(1, max |J|)


def central_difference(residual, q: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """F (B, m) and dF/dq (B, m, n) of ``residual(q (B, n), y (B, k))`` by central differences, all
    2n + 1 shifted copies of the batch in one numpy call (step :data:`FD_STEP` x max(1, |q_j|))."""
    B, n = q.shape
    shifted = np.repeat(q[None], 2 * n + 1, axis=0)  # (2n + 1, B, n): q, q + h e_j, q - h e_j
    j = np.arange(n)
    h = (FD_STEP * np.maximum(1.0, np.abs(q))).T  # (n, B)
    shifted[1 + j, :, j] += h
    shifted[1 + n + j, :, j] -= h
    step = shifted[1 + j, :, j] - shifted[1 + n + j, :, j]  # (n, B): the steps as represented
    F = np.asarray(residual(shifted.reshape(-1, n), np.tile(y, (2 * n + 1, 1))), dtype=float)
    F = F.reshape(2 * n + 1, B, F.shape[1])
    J = (F[1:n + 1] - F[n + 1:]) / step[:, :, None]  # (n, B, m)
    return F[0], J.transpose(1, 2, 0)


class ConstraintCallback:
    """Constraint parts that are not built in, at their condition, as the core calls them (one call per
    batch of configurations): :meth:`residuals` of ``q (B, n)``, with the Jacobian when asked; ``parts``:
    (constraint, y (k,)) in residual order. A part's analytic :meth:`~manifoldgen.constraints.Constraint.jacobian`
    is used as is; for a part that has none (torch autograd by default), batches up to :data:`FD_ROWS`
    residual rows take :func:`central_difference` on its numpy residual (equal to autograd within ~1e-9; first
    checked against autograd on the first call's rows, and autograd kept for a part that disagrees, as a
    float32 or non-smooth residual would, with a warning), larger ones autograd."""

    def __init__(self, parts: list[tuple[Constraint, np.ndarray]]):
        self.parts = parts
        self._differences: dict[int, bool] = {}  # part index -> central differences checked and agreeing

    @property
    def rows(self) -> int:
        return sum(part.m for part, _ in self.parts)

    def residuals(self, q: np.ndarray, jacobian: bool):
        """F (B, rows), or (F, J (B, rows, n)) when ``jacobian``."""
        ys = [np.broadcast_to(y, (len(q), len(y))) for _, y in self.parts]
        if not jacobian:
            return _joined([part.residual(q, y) for (part, _), y in zip(self.parts, ys)])
        pairs = [self._jacobian(i, q, y) for i, y in enumerate(ys)]
        return _joined([F for F, _ in pairs]), _joined([J for _, J in pairs])

    def _jacobian(self, i: int, q: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        part = self.parts[i][0]
        if own_jacobian(part) or (2 * q.shape[1] + 1) * len(q) > FD_ROWS:
            return part.jacobian(q, y)
        if i not in self._differences:
            self._differences[i] = self._agrees(part, q[:8], y[:8])
        return central_difference(part.residual, q, y) if self._differences[i] else part.jacobian(q, y)

    @staticmethod
    def _agrees(part: Constraint, q: np.ndarray, y: np.ndarray) -> bool:
        """Whether :func:`central_difference` matches ``part``'s autograd Jacobian on these rows (else a warning)."""
        _, J = part.jacobian(q, y)
        error = float(np.max(np.abs(central_difference(part.residual, q, y)[1] - J), initial=0.0))
        if error <= FD_AGREE * max(1.0, float(np.max(np.abs(J), initial=0.0))):
            return True
        warnings.warn(f"constraint '{part.spec()['type']}': central differences of its numpy residual differ from "
                      f"its torch autograd Jacobian by {error:.1e} (a float32 or non-smooth residual?), so the core "
                      "calls autograd for it (slower); an analytic jacobian() in the class makes it fast",
                      stacklevel=2)
        return False


def _joined(blocks: list[np.ndarray]) -> np.ndarray:
    """The parts' blocks side by side along axis 1, as the C-contiguous float64 array the core reads."""
    return np.ascontiguousarray(blocks[0] if len(blocks) == 1 else np.concatenate(blocks, axis=1), dtype=float)
