"""Batched SO(3) helpers: log map (numpy or differentiable torch) and its Jacobian."""

from __future__ import annotations

import numpy as np

from manifoldgen.robot import is_tensor


def hat(w: np.ndarray) -> np.ndarray:
    """(B, 3) -> (B, 3, 3) skew-symmetric matrices."""
    S = np.zeros((*w.shape[:-1], 3, 3))
    S[..., 0, 1], S[..., 0, 2], S[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    S[..., 1, 0], S[..., 2, 0], S[..., 2, 1] = w[..., 2], -w[..., 1], w[..., 0]
    return S


def log3(R):
    """(B, 3, 3) rotations -> (B, 3) rotation vectors (angle in [0, pi]); numpy or torch like ``R``."""
    if is_tensor(R):
        return _log3_torch(R)
    cos = np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
    theta = np.arccos(cos)
    vee = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
    small = theta < 1e-6
    near_pi = theta > np.pi - 1e-4
    scale = np.where(small, 0.5 + theta**2 / 12, theta / (2 * np.sin(np.where(small | near_pi, 1.0, theta))))
    w = scale[:, None] * vee
    if near_pi.any():  # axis from the symmetric part, sign from the antisymmetric part
        Rp = R[near_pi]
        k = np.argmax(np.diagonal(Rp, axis1=1, axis2=2), axis=1)  # the largest |a_k|
        sym = (Rp + np.transpose(Rp, (0, 2, 1))) / 2
        rows = sym[np.arange(len(k)), k] - cos[near_pi, None] * np.eye(3)[k]  # (1 - cos) a_k a
        axis = rows / np.linalg.norm(rows, axis=1, keepdims=True)
        sign = np.sign(np.sum(axis * vee[near_pi], axis=1))
        sign[sign == 0] = 1.0
        w[near_pi] = axis * (theta[near_pi] * sign)[:, None]
    return w


def jlog3(w: np.ndarray) -> np.ndarray:
    """(B, 3) rotation vectors -> (B, 3, 3) Jacobian of log3 w.r.t. a right perturbation."""
    theta = np.linalg.norm(w, axis=1)
    small = theta < 1e-4
    t = np.where(small, 1.0, theta)
    coef = np.where(small, 1 / 12 + theta**2 / 720, 1 / t**2 - (1 + np.cos(t)) / (2 * t * np.sin(t)))
    W = hat(w)
    return np.eye(3) + 0.5 * W + coef[:, None, None] * (W @ W)


def _log3_torch(R):
    """Differentiable torch log map: angle from atan2 (finite gradients at the identity); within
    1e-4 rad of pi the axis comes from the symmetric part, as in the numpy path."""
    import torch

    vee = torch.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], dim=1)
    cos = (R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2] - 1) / 2
    sin = torch.sqrt((vee * vee).sum(dim=1) + 1e-30) / 2
    theta = torch.atan2(sin, cos)
    scale = torch.where(theta < 1e-6, 0.5 + theta**2 / 12, theta / (2 * sin.clamp(min=1e-12)))
    w = scale[:, None] * vee
    near_pi = theta > np.pi - 1e-4
    if bool(near_pi.any()):
        Rp, c = R[near_pi], cos[near_pi]
        k = torch.argmax(torch.diagonal(Rp, dim1=1, dim2=2), dim=1)
        sym = (Rp + Rp.transpose(1, 2)) / 2
        rows = sym[torch.arange(len(k)), k] - c[:, None] * torch.eye(3, dtype=R.dtype)[k]
        axis = rows / torch.linalg.vector_norm(rows, dim=1, keepdim=True)
        sign = torch.sign((axis * vee[near_pi]).sum(dim=1))
        sign = torch.where(sign == 0, torch.ones_like(sign), sign)
        w = w.clone()
        w[near_pi] = axis * (theta[near_pi] * sign)[:, None]
    return w
