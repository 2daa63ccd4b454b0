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
    """(S, 4, 4, B) transforms ``A + u B + v C`` of the steps with ``constants`` (3, S, 4, 4, 1) at ``q`` (B, n),
    the batch last."""
    angle = q[:, columns].T.contiguous()
    u = torch.where(revolute[:, None], torch.sin(angle), angle) if prismatic else torch.sin(angle)
    return constants[0] + u[:, None, None] * constants[1] + (1 - torch.cos(angle))[:, None, None] * constants[2]


def _times(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(k, 4, 4, B) products ``a @ b`` of the transforms ``a``, ``b`` (k, 4, 4, B), batch last: a broadcast product
    and a sum, each over contiguous rows of B values (twice as fast, backward included, as torch's batched matrix
    product of 4 x 4 matrices)."""
    return (a[:, :, :, None] * b[:, None]).sum(2)


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
                self._tensors[key] = (torch.as_tensor(chain.constants, dtype=dtype)[..., None], chain.columns,
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
        if len(chain) == 1:  # nothing in the planning group moves the frame
            T = chain[0].expand(len(q), 4, 4)
            return T[:, :3, 3], T[:, :3, :3]
        M = _step_transforms(*chain, q)
        while len(M) > 1:  # pairs unbound, not strided slices (whose backward fills zero tensors)
            M = _times(*M.unflatten(0, (-1, 2)).unbind(1))
        return M[0, :3, 3].T, M[0, :3, :3].permute(2, 0, 1)

    def _com(self, q: torch.Tensor) -> torch.Tensor:
        key = ("com", q.dtype)
        if key not in self._tensors:
            tree = self.robot._tree
            self._tensors[key] = (torch.as_tensor(tree.constants, dtype=q.dtype)[..., None], tree.columns,
                                  torch.as_tensor(tree.revolute), not tree.revolute.all(), tree.levels,
                                  torch.as_tensor(tree.weights, dtype=q.dtype),
                                  torch.as_tensor(tree.fixed, dtype=q.dtype))
        constants, columns, revolute, prismatic, levels, weights, fixed = self._tensors[key]
        M = _step_transforms(constants, columns, revolute, prismatic, q)
        if levels:  # one split, not a slice per depth (whose backward pass fills a zero tensor as large as M)
            depths = torch.split(M, [levels[0][0].start] + [steps.stop - steps.start for steps, _ in levels])
        world = [depths[0]] if levels else [M]  # depth 0 is in the world already
        above = 0  # where the depth above starts: a step's parent is one of its steps
        for (steps, parents), moved in zip(levels, depths[1:] if levels else ()):
            local = slice(parents.start - above, parents.stop - above) if isinstance(parents, slice) \
                else parents - above
            world.append(_times(world[-1][local], moved))
            above = steps.start
        world = torch.cat(world) if len(world) > 1 else world[0]
        return (world.reshape(-1, len(q)).T @ weights + fixed) / self.robot.mass
