"""Sample-quality metrics: constraint satisfaction (raw and refined) and coverage of the manifold.

Coverage compares generated rows with a dense reference set on the manifold (fresh
projection samples at the same condition): the k-NN precision, recall, density and coverage
of Naeem et al. 2020 ("Reliable Fidelity and Diversity Metrics for Generative Models") and
the kernel MMD. Joint-space features are scaled by the joint ranges so every joint counts alike.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch

from manifoldgen.constraints import Constraint, project

CHUNK_ROWS = 2048


def _kth_neighbour_radius(x: torch.Tensor, k: int) -> torch.Tensor:
    """(N,) distance from each row of x (N, D) to its k-th nearest other row."""
    radii = torch.empty(len(x), dtype=x.dtype)
    for start in range(0, len(x), CHUNK_ROWS):
        d = torch.cdist(x[start:start + CHUNK_ROWS], x)
        radii[start:start + CHUNK_ROWS] = torch.topk(d, k + 1, dim=1, largest=False).values[:, k]
    return radii


@dataclass
class PRDC:
    """k-NN fidelity (precision, density) and diversity (recall, coverage) of fake vs real."""

    precision: float
    recall: float
    density: float
    coverage: float

    def to_dict(self) -> dict:
        return asdict(self)


def prdc(real: np.ndarray, fake: np.ndarray, k: int = 5) -> PRDC:
    """Naeem et al. 2020 metrics of ``fake (M, D)`` against ``real (N, D)`` (both need > k rows).

    precision: fraction of fake rows inside some real row's k-NN ball; recall: fraction of real
    rows inside some fake row's k-NN ball; density: mean count of real balls holding a fake
    row, divided by k; coverage: fraction of real balls holding at least one fake row.
    """
    x = torch.as_tensor(np.asarray(real, np.float64))
    y = torch.as_tensor(np.asarray(fake, np.float64))
    if len(x) <= k or len(y) <= k:
        raise ValueError(f"prdc needs more than k={k} rows in each set, got {len(x)} and {len(y)}")
    r_real, r_fake = _kth_neighbour_radius(x, k), _kth_neighbour_radius(y, k)
    in_real_balls = torch.zeros(len(y))  # per fake row: number of real balls containing it
    real_covered = torch.zeros(len(x), dtype=torch.bool)  # per real row: some fake row in its ball
    real_recalled = torch.zeros(len(x), dtype=torch.bool)  # per real row: inside some fake ball
    for start in range(0, len(y), CHUNK_ROWS):
        d = torch.cdist(y[start:start + CHUNK_ROWS], x)  # (m, N)
        inside = d <= r_real[None]
        in_real_balls[start:start + CHUNK_ROWS] = inside.sum(1).to(in_real_balls.dtype)
        real_covered |= inside.any(0)
        real_recalled |= (d <= r_fake[start:start + CHUNK_ROWS, None]).any(0)
    return PRDC(precision=float((in_real_balls > 0).double().mean()), recall=float(real_recalled.double().mean()),
                density=float(in_real_balls.double().mean() / k), coverage=float(real_covered.double().mean()))


def mmd(real: np.ndarray, fake: np.ndarray, bandwidth: float | None = None) -> float:
    """Unbiased squared MMD with a Gaussian kernel (bandwidth: median real-real distance by default)."""
    x = torch.as_tensor(np.asarray(real, np.float64))
    y = torch.as_tensor(np.asarray(fake, np.float64))
    dxx, dyy, dxy = torch.cdist(x, x), torch.cdist(y, y), torch.cdist(x, y)
    if bandwidth is None:
        bandwidth = float(torch.median(dxx[torch.triu_indices(len(x), len(x), 1).unbind()]))
    kxx, kyy, kxy = (torch.exp(-d.pow(2) / (2 * bandwidth ** 2)) for d in (dxx, dyy, dxy))
    n, m = len(x), len(y)
    return float((kxx.sum() - n) / (n * (n - 1)) + (kyy.sum() - m) / (m * (m - 1)) - 2 * kxy.mean())


def joint_features(q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """(B, n) configurations scaled to [0, 1] per joint range."""
    return (np.asarray(q) - lower) / np.maximum(upper - lower, 1e-9)


@dataclass
class Accuracy:
    """Constraint satisfaction at the tolerance for one condition value."""

    raw: float  # fraction of generated rows within tolerance (and limits)
    refined: float  # fraction within tolerance after at most ``refine`` projection iterations
    refine: int
    residual: np.ndarray  # (B,) worst |F_i| / tol_i of the raw rows (for histograms)

    def to_dict(self) -> dict:
        return {"raw": self.raw, "refined": self.refined, "refine": self.refine,
                "median_violation": float(np.median(self.residual))}


def accuracy(constraint: Constraint, q: np.ndarray, y: np.ndarray, refine: int = 3) -> tuple[Accuracy, np.ndarray]:
    """Satisfaction of ``q (B, n)`` at ``y`` raw and after ``refine`` LM iterations; also the refined rows."""
    refined = project(constraint, q, y, max_iters=refine).q if refine else q
    raw_ok, refined_ok = constraint.satisfied(q, y), constraint.satisfied(refined, y)
    return Accuracy(float(raw_ok.mean()), float(refined_ok.mean()), refine, constraint.violation(q, y)), refined


def coverage_metrics(reference: np.ndarray, generated: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                     k: int = 5, mmd_rows: int = 2000) -> dict:
    """PRDC and MMD of generated rows against reference rows on the manifold (joint-range scaled)."""
    real, fake = joint_features(reference, lower, upper), joint_features(generated, lower, upper)
    result = prdc(real, fake, k).to_dict()
    result["mmd"] = mmd(real[:mmd_rows], fake[:mmd_rows])
    return result
