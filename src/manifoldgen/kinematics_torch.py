"""The differentiable torch path of the robot's batched kinematics.

Walks the same tree description as :class:`manifoldgen.robot.Robot`'s numpy path (its
``_links``: placements and elementary motions of the planning group), on ``q (B, n)``
tensors of any float dtype, so that any constraint's residual, written once against
``Robot.frame_pose`` / ``Robot.com``, is differentiable for the models' training penalty.
:class:`Robot` dispatches here when it is given a tensor.
"""

from __future__ import annotations

import torch


class TorchKinematics:
    """Frame poses and centre of mass of ``robot`` for ``q (B, n)`` tensors."""

    def __init__(self, robot):
        self.robot = robot
        self._constants: dict[torch.dtype, dict] = {}

    def _link_constants(self, dtype: torch.dtype) -> dict:
        """Per joint id: placement rotation (3, 3), translation (3,), motions [(kind, axis, K, K @ K, col)]."""
        if dtype not in self._constants:
            table = {}
            for jid, link in self.robot._links.items():
                P = torch.as_tensor(link.placement, dtype=dtype)
                motions = []
                for m in link.motions:
                    axis = torch.as_tensor(m.axis, dtype=dtype)
                    x, y, z = m.axis
                    K = torch.tensor([[0, -z, y], [z, 0, -x], [-y, x, 0]], dtype=dtype)
                    motions.append((m.kind, axis, K, K @ K, m.index))
                table[jid] = (P[:3, :3], P[:3, 3], motions)
            self._constants[dtype] = table
        return self._constants[dtype]

    def world(self, q: torch.Tensor, joint_ids: list[int]) -> dict[int, tuple[torch.Tensor, torch.Tensor]]:
        """World rotation (B, 3, 3) and position (B, 3) of the given joints (and their ancestors)."""
        table = self._link_constants(q.dtype)
        needed = sorted({a for j in joint_ids for a in self.robot._ancestors(j)})
        eye = torch.eye(3, dtype=q.dtype)
        world = {0: (eye.expand(len(q), 3, 3), torch.zeros(len(q), 3, dtype=q.dtype))}
        for jid in needed:
            R, p = world[self.robot._links[jid].parent]
            PR, Pp, motions = table[jid]
            p = p + R @ Pp
            R = R @ PR
            for kind, axis, K, K2, col in motions:
                angle = q[:, col]
                if kind == "P":
                    p = p + (R @ axis) * angle[:, None]
                else:
                    s, c = torch.sin(angle)[:, None, None], torch.cos(angle)[:, None, None]
                    R = R @ (eye + s * K + (1 - c) * K2)
            world[jid] = (R, p)
        return world

    def frame_pose(self, q: torch.Tensor, frame: str) -> tuple[torch.Tensor, torch.Tensor]:
        """World position (B, 3) and rotation (B, 3, 3) of ``frame``."""
        f = self.robot.model.frames[self.robot.frame_id(frame)]
        R, p = self.world(q, [f.parentJoint])[f.parentJoint]
        placement = torch.as_tensor(f.placement.homogeneous, dtype=q.dtype)
        return p + R @ placement[:3, 3], R @ placement[:3, :3]

    def com(self, q: torch.Tensor) -> torch.Tensor:
        """Centre of mass (B, 3)."""
        bodies = self.robot._bodies
        world = self.world(q, [j for j, _, _ in bodies])
        total = torch.zeros(len(q), 3, dtype=q.dtype)
        for jid, mass, lever in bodies:
            R, p = world[jid]
            total = total + mass * (p + R @ torch.as_tensor(lever[:3], dtype=q.dtype))
        return total / self.robot.mass
