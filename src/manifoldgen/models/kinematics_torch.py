"""Differentiable torch port of the robot's batched forward kinematics and of the pose residual.

Built once from ``robot._links`` (placements and elementary motions of the tree), it maps
``q (B, n)`` tensors to frame poses so that a model can be trained with a penalty on the
constraint residual of its own samples. Only used at training time; sampling never needs it.
"""

from __future__ import annotations

import numpy as np
import torch

from manifoldgen.constraints import Constraint, ConstraintSet, PoseConstraint
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot


class TorchFrameKinematics(torch.nn.Module):
    """World pose of one frame: ``forward(q (B, n)) -> p (B, 3), R (B, 3, 3)``."""

    def __init__(self, robot: Robot, frame: str):
        super().__init__()
        f = robot.model.frames[robot.frame_id(frame)]
        self._chain: list[tuple[str, list[tuple[str, int]]]] = []
        for i, jid in enumerate(robot._ancestors(f.parentJoint)):
            link = robot._links[jid]
            self.register_buffer(f"placement{i}", torch.as_tensor(link.placement, dtype=torch.float32))
            motions = []
            for k, m in enumerate(link.motions):
                self.register_buffer(f"axis{i}_{k}", torch.as_tensor(m.axis, dtype=torch.float32))
                motions.append((m.kind, m.index))
            self._chain.append((f"placement{i}", motions))
        self.register_buffer("frame_placement", torch.as_tensor(f.placement.homogeneous, dtype=torch.float32))

    def forward(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        R = torch.eye(3, dtype=q.dtype).expand(len(q), 3, 3)
        p = torch.zeros(len(q), 3, dtype=q.dtype)
        for i, (name, motions) in enumerate(self._chain):
            P = getattr(self, name).to(q.dtype)
            p = p + (R @ P[:3, 3])
            R = R @ P[:3, :3]
            for k, (kind, col) in enumerate(motions):
                axis = getattr(self, f"axis{i}_{k}").to(q.dtype)
                if kind == "P":
                    p = p + R @ axis * q[:, col:col + 1]
                else:
                    R = R @ _rodrigues(axis, q[:, col])
        F = self.frame_placement.to(q.dtype)
        return p + R @ F[:3, 3], R @ F[:3, :3]


def _rodrigues(axis: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """(B, 3, 3) rotations by ``angle (B,)`` about a fixed unit ``axis (3,)``."""
    x, y, z = axis.tolist()
    K = torch.tensor([[0, -z, y], [z, 0, -x], [-y, x, 0]], dtype=angle.dtype)
    s, c = torch.sin(angle)[:, None, None], torch.cos(angle)[:, None, None]
    return torch.eye(3, dtype=angle.dtype) + s * K + (1 - c) * (K @ K)


class TorchPoseResidual(torch.nn.Module):
    """Squared normalised residual of a :class:`PoseConstraint`: ``forward(q, y) -> (B,)``.

    Position components contribute ``((p_a - y_a) / tol)^2``; orientation contributes
    ``2 (1 - cos theta) / tol^2`` (= theta^2 / tol^2 near the target, smooth everywhere).
    """

    def __init__(self, constraint: PoseConstraint):
        super().__init__()
        self.fk = TorchFrameKinematics(constraint.robot, constraint.frame)
        self.register_buffer("target", torch.as_tensor(constraint.rotation, dtype=torch.float32))
        self.axes = list(constraint._idx)
        self.k = len(self.axes)
        self.position_tol = float(constraint.tolerance[0]) if self.k else 1.0
        self.orientation_tol = float(constraint.tolerance[-1])

    def forward(self, q: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        p, R = self.fk(q)
        position = ((p[:, self.axes] - y) / self.position_tol).pow(2).sum(dim=1)
        cos_sum = (self.target.to(q.dtype).unsqueeze(0) * R).sum(dim=(1, 2))  # trace(R_t^T R)
        return position + (3.0 - cos_sum) / self.orientation_tol ** 2


class TorchResidual(torch.nn.Module):
    """Sum of squared normalised residuals of a constraint (pose or a set of poses)."""

    def __init__(self, constraint: Constraint):
        super().__init__()
        parts = constraint.parts if isinstance(constraint, ConstraintSet) else [constraint]
        unsupported = [type(c).__name__ for c in parts if not isinstance(c, PoseConstraint)]
        if unsupported:
            raise ManifoldgenError(f"no torch residual for {', '.join(unsupported)}; "
                                   "train with residual_weight=0 for this constraint")
        self.parts = torch.nn.ModuleList(TorchPoseResidual(c) for c in parts)
        self.cuts = np.cumsum([0] + [c.k for c in self.parts]).tolist()

    def forward(self, q: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """(B, n), (B, k) -> (B,) sum_i (F_i / tol_i)^2 (smooth orientation term)."""
        return sum(part(q, y[:, a:b]) for part, a, b in zip(self.parts, self.cuts[:-1], self.cuts[1:]))
