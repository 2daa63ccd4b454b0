"""The differentiable torch path of the robot's batched kinematics.

Evaluates the same step products as :class:`manifoldgen.robot.Robot`'s numpy path (each elementary motion an
affine function ``A + u B + v C`` of ``sin`` and ``1 - cos`` of its angle; a frame is the product of its chain's
steps, taken pairwise; the centre of mass composes the body-moving steps depth by depth), on ``q (B, n)`` tensors
of any float dtype, so that any constraint's residual, written once against ``Robot.frame_pose`` / ``Robot.com``,
is differentiable for the models' training penalty. A whole chain costs a handful of tensor operations (not a few
per joint), which keeps the penalty's forward and backward passes cheap on robots with many joints.
:class:`Robot` dispatches here when it is given a tensor.
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import torch


def _step_transforms(constants: torch.Tensor, columns: np.ndarray, revolute: torch.Tensor, prismatic: bool,
                     q: torch.Tensor) -> torch.Tensor:
    """(B, S, 4, 4) transforms ``A + u B + v C`` of the steps with ``constants`` (3, S, 4, 4) at ``q`` (B, n)."""
    angle = q[:, columns]
    u = torch.where(revolute, torch.sin(angle), angle) if prismatic else torch.sin(angle)
    return constants[0] + u[..., None, None] * constants[1] + (1 - torch.cos(angle))[..., None, None] * constants[2]


class TorchKinematics:
    """Frame poses and centre of mass of ``robot`` for ``q (B, n)`` tensors."""

    def __init__(self, robot):
        self.robot = robot
        self._tensors: dict[tuple, tuple] = {}  # (frame or "com", dtype) -> its constants as tensors
        self._shared: dict | None = None  # inside shared(): (frame or "com", id(q)) -> (q, its value)

    @contextmanager
    def shared(self):
        """Within it, a frame or the centre of mass asked for twice at the same tensor is computed once (one
        graph): a constraint's residual and inequality read the same frames in one penalty."""
        self._shared = {}
        try:
            yield
        finally:
            self._shared = None

    def _remembered(self, q: torch.Tensor, key: str, compute):
        if self._shared is None:
            return compute(q)
        mark = (key, id(q), q._version)
        if mark not in self._shared:
            self._shared[mark] = (q, compute(q))  # q kept: its id is not reused while shared
        return self._shared[mark][1]

    def _chain(self, frame: str, dtype: torch.dtype) -> tuple:
        key = (frame, dtype)
        if key not in self._tensors:
            chain = self.robot.chain_of(frame)
            if isinstance(chain, np.ndarray):  # nothing in the planning group moves the frame
                self._tensors[key] = (torch.as_tensor(chain, dtype=dtype),)
            else:
                self._tensors[key] = (torch.as_tensor(chain.constants, dtype=dtype), chain.columns,
                                      torch.as_tensor(chain.revolute), chain.prismatic)
        return self._tensors[key]

    def frame_pose(self, q: torch.Tensor, frame: str) -> tuple[torch.Tensor, torch.Tensor]:
        """World position (B, 3) and rotation (B, 3, 3) of ``frame``."""
        return self._remembered(q, frame, lambda q: self._frame_pose(q, frame))

    def com(self, q: torch.Tensor) -> torch.Tensor:
        """Centre of mass (B, 3)."""
        return self._remembered(q, "com", self._com)

    def _frame_pose(self, q: torch.Tensor, frame: str) -> tuple[torch.Tensor, torch.Tensor]:
        chain = self._chain(frame, q.dtype)
        if len(chain) == 1:
            T = chain[0].expand(len(q), 4, 4)
        else:
            M = _step_transforms(*chain, q)
            while M.shape[1] > 1:  # pairs unbound, not strided slices (whose backward fills zero tensors)
                first, second = M.unflatten(1, (-1, 2)).unbind(2)
                M = first @ second
            T = M[:, 0]
        return T[:, :3, 3], T[:, :3, :3]

    def _com(self, q: torch.Tensor) -> torch.Tensor:
        key = ("com", q.dtype)
        if key not in self._tensors:
            tree = self.robot._tree
            self._tensors[key] = (torch.as_tensor(tree.constants, dtype=q.dtype), tree.columns,
                                  torch.as_tensor(tree.revolute), not tree.revolute.all(), tree.levels,
                                  torch.as_tensor(tree.weights, dtype=q.dtype),
                                  torch.as_tensor(tree.fixed, dtype=q.dtype))
        constants, columns, revolute, prismatic, levels, weights, fixed = self._tensors[key]
        M = _step_transforms(constants, columns, revolute, prismatic, q)
        if levels:  # one split, not a slice per depth (whose backward pass fills a zero tensor as large as M)
            depths = torch.split(M, [levels[0][0].start] + [steps.stop - steps.start for steps, _ in levels], dim=1)
        world = [depths[0]] if levels else [M]  # depth 0 is in the world already
        above = 0  # where the depth above starts: a step's parent is one of its steps
        for (steps, parents), moved in zip(levels, depths[1:] if levels else ()):
            local = slice(parents.start - above, parents.stop - above) if isinstance(parents, slice) \
                else parents - above
            world.append(world[-1][:, local] @ moved)
            above = steps.start
        world = torch.cat(world, dim=1) if len(world) > 1 else world[0]
        return (world.reshape(len(q), -1) @ weights + fixed) / self.robot.mass
