"""The numpy path of the batched kinematics: a planning group's tree as elementary motions ("steps"), each an
affine function of the sine and cosine of its angle with precomputed constants; a frame's pose is the pairwise
product of its chain's steps, the centre of mass the body-moving steps composed depth by depth. Shapes: ``q (B, n)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from manifoldgen.errors import ManifoldgenError

@dataclass(frozen=True)
class Motion:
    """One elementary joint motion: rotation about or translation along a local axis."""

    kind: str  # "R" or "P"
    axis: np.ndarray  # (3,) unit axis in the joint frame
    index: int  # column in q


@dataclass(frozen=True)
class Link:
    """A joint of the full model seen from the planning group."""

    parent: int  # full-model joint id of the parent (0 = universe)
    placement: np.ndarray  # (4, 4) parent joint frame -> this joint, before motion
    motions: tuple[Motion, ...]  # empty for a locked joint (its motion is in placement)


@dataclass(frozen=True)
class Step:
    """One elementary motion of the tree as an affine function of two numbers: its transform from the
    previous step's frame (after that step's motion) is ``A + u B + v C``, with ``u = sin, v = 1 - cos`` of
    the angle for a revolute motion and ``u`` = the displacement (``C = 0``) for a prismatic one."""

    parent: int  # index of the previous step (-1: the world)
    constants: np.ndarray  # (3, 4, 4) A (the fixed transforms before the motion), A @ E, A @ E @ E
    column: int  # column in q
    revolute: bool


@dataclass(frozen=True)
class Chain:
    """The steps from the world to one frame, padded with identities to a power of two (>= 1) steps:
    the frame's transform is the ordered product of the steps', the frame's own placement folded into
    the last one."""

    constants: np.ndarray  # (3, P, 4, 4) A, B, C of each step
    columns: np.ndarray  # (P,) column in q (0 for padding)
    revolute: np.ndarray  # (P,) bool
    prismatic: bool  # any prismatic step (else u = sin of every angle)


@dataclass(frozen=True)
class Tree:
    """The steps that move the robot's bodies, by depth, and each step's mass-weighted body points."""

    constants: np.ndarray  # (3, S, 4, 4)
    columns: np.ndarray  # (S,)
    revolute: np.ndarray  # (S,) bool
    levels: tuple[tuple[slice, slice | np.ndarray], ...]  # per depth from 1: (its steps, their parents)
    weights: np.ndarray  # (S * 16, 3): flattened world transforms (B, S * 16) @ weights = sum of mass * world point
    fixed: np.ndarray  # (3,) sum of mass * world point of the bodies no step moves


def is_tensor(x) -> bool:
    """True for a torch tensor (checked without importing torch)."""
    return type(x).__module__.startswith("torch")


def is_traced(x) -> bool:
    """True for a traced array (:mod:`manifoldgen.constraints.trace`): its kinematics are recorded, not computed."""
    return hasattr(type(x), "traced_frame_pose")


def as_batch(q: np.ndarray, n: int) -> np.ndarray:
    """Promote (n,) to (1, n) and check the width."""
    q = np.asarray(q, dtype=float)
    if q.ndim == 1:
        q = q[None]
    if q.ndim != 2 or q.shape[1] != n:
        raise ManifoldgenError(f"expected configurations of shape (B, {n}), got {q.shape}")
    return q


CELLS = 2048  # rows x steps per evaluation of step products: larger batches go in chunks that stay in cache


def in_chunks(evaluate, steps, q: np.ndarray, count: int) -> np.ndarray:
    """``evaluate(steps, q)`` on chunks of ``q`` (B, n) of at most ``CELLS / count`` rows, concatenated."""
    rows = max(1, CELLS // max(count, 1))
    if len(q) <= rows:
        return evaluate(steps, q)
    return np.concatenate([evaluate(steps, q[i:i + rows]) for i in range(0, len(q), rows)])


def step_transforms(constants: np.ndarray, columns: np.ndarray, revolute: np.ndarray, prismatic: bool,
                     q: np.ndarray) -> np.ndarray:
    """(B, S, 4, 4) transforms ``A + u B + v C`` of the steps with ``constants`` (3, S, 4, 4) at ``q`` (B, n)."""
    angle = q[:, columns]
    u = np.where(revolute, np.sin(angle), angle) if prismatic else np.sin(angle)
    M = u[..., None, None] * constants[1]
    M += constants[0]
    M += (1 - np.cos(angle))[..., None, None] * constants[2]
    return M


def chain_product(chain: Chain, q: np.ndarray) -> np.ndarray:
    """(B, 4, 4) world transform of a chain's frame: the steps' product, pairwise (log2 P batched products)."""
    M = step_transforms(chain.constants, chain.columns, chain.revolute, chain.prismatic, q)
    while M.shape[1] > 1:
        M = M[:, 0::2] @ M[:, 1::2]
    return M[:, 0]


def tree_com(tree: Tree, q: np.ndarray) -> np.ndarray:
    """(B, 3) mass-weighted sum of the body points of ``tree`` at ``q`` (B, n), depth by depth."""
    M = step_transforms(tree.constants, tree.columns, tree.revolute, not tree.revolute.all(), q)
    for steps, parents in tree.levels:  # depth 0 is in the world already
        M[:, steps] = M[:, parents] @ M[:, steps]
    return M.reshape(len(q), -1) @ tree.weights + tree.fixed


def motion_transform(m: Motion, angle: np.ndarray) -> np.ndarray:
    """(B, 4, 4) homogeneous transform of a revolute or prismatic motion."""
    T = np.zeros((len(angle), 4, 4))
    T[:, 3, 3] = 1.0
    if m.kind == "P":
        T[:, :3, :3] = np.eye(3)
        T[:, :3, 3] = angle[:, None] * m.axis
        return T
    x, y, z = m.axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    T[:, :3, :3] = np.eye(3) + s * K + (1 - c) * (K @ K)
    return T
