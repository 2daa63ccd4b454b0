"""CBiRRT (Berenson et al. 2011): RRT-Connect toward raw samples, every step projected onto the manifold."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning.base import PlannerSettings
from manifoldgen.planning.rrt_connect import RRTConnect
from manifoldgen.sampling import Sampler, UniformSampler
from manifoldgen.space import ConstrainedSpace


@dataclass
class CBiRRTSettings(PlannerSettings):
    """targets: raw sampler candidates generated per batch (the random targets)."""

    targets: int = 64

    def check(self) -> None:
        super().check()
        if self.targets <= 0:
            raise ManifoldgenError(f"targets must be positive, got {self.targets}")


class CBiRRT(RRTConnect):
    """Constrained bidirectional RRT. Targets are the sampler's raw candidates, unchecked
    (uniform in the joint limits with the ``uniform`` sampler or none, as in the paper);
    extensions always use the ``project`` local planner (ConstrainedExtend), whatever
    ``local`` says."""

    name = "cbirrt"
    settings_type = CBiRRTSettings

    def __init__(self, space: ConstrainedSpace, sampler: Sampler | None = None, *, local: str = "project",
                 seed: int = 0, settings: CBiRRTSettings | None = None):
        sampler = UniformSampler(space, seed=seed) if sampler is None else sampler
        super().__init__(space, sampler, local="project", seed=seed, settings=settings)
        self._raw = np.zeros((0, space.n))

    def _target(self) -> np.ndarray:
        if not len(self._raw):
            self._raw = self.sampler.candidates(self.settings.targets)
            self.sampler.stats.generated += len(self._raw)
        self.samples += 1
        q, self._raw = self._raw[0], self._raw[1:]
        return q
