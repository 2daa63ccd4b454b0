"""Conditional flow matching (rectified flow): a velocity field integrated from noise to configurations.

Training regresses a velocity MLP ``v(x_t, t, y)`` onto ``x1 - x0`` along straight interpolants
``x_t = (1 - t) x0 + t x1`` between ``x0 ~ N(0, I)`` and a normalised data row ``x1``: a plain regression,
with no encoder or critic to collapse onto one IK branch. Sampling integrates ``dx/dt = v`` from noise: ``steps - 1``
Heun steps, then one Euler step, which is the one-step endpoint estimate ``x_t + (1 - t) v``. The compiled
core integrates it the same way (:meth:`native_decoder`, ``steps`` of ``manifoldgen_core.Decoder``).

Beyond the plain objective, ``residual_weight`` weighs the constraint residual of that last step for
samples (``penalty_fraction`` of a batch) at conditions drawn across the trained range: the earlier steps
run without gradient, so the penalty trains the velocity where the sampler ends, at the cost of one
sampling pass of those rows per batch.
"""

from __future__ import annotations

import torch

from manifoldgen.errors import ManifoldgenError
from manifoldgen.models.adam import Adam
from manifoldgen.models.base import SingleLossSampler, heun_steps, last_step, mlp, velocity_at


class ConditionalFlowMatching(SingleLossSampler):
    """Velocity MLP on ``[x_t, y, t]``; ``steps`` network-evaluated steps from t = 0 to 1 per sample."""

    name = "cfm"
    defaults = {"hidden": [256, 256], "steps": 8, "lr": 1e-3, "batch": 256, "epochs": 60, "patience": 15,
                "residual_weight": 0.3, "penalty_fraction": 0.25}

    def __init__(self, **hyper):
        super().__init__(**hyper)
        fraction = self.config["penalty_fraction"]
        if not 0 < fraction <= 1:
            raise ManifoldgenError(f"hyper-parameter penalty_fraction={fraction!r} of model 'cfm' must be in (0, 1] "
                                   "(the share of each batch whose samples the residual penalty sees)")

    def _build(self) -> None:
        self.nets["velocity"] = mlp(self.d + self.k + 1, self.config["hidden"], self.d)

    def _before_last(self, y: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
        """States (B, d) at t = 1 - 1/steps: noise (B, d) carried by ``steps - 1`` Heun steps."""
        return heun_steps(self.nets["velocity"], torch.randn(len(y), self.d, generator=generator), y,
                          self.config["steps"])

    def _last(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """The final Euler step from t = 1 - 1/steps to 1 (B, d)."""
        return last_step(self.nets["velocity"], x, y, self.config["steps"])

    def _generate(self, y, generator):
        return self._last(self._before_last(y, generator), y)

    def _sampling_net(self):
        return self.nets["velocity"], "normal"

    def _integration_steps(self) -> int:
        return int(self.config["steps"])

    def _optimizers(self):
        return [Adam(self.nets.parameters(), lr=self.config["lr"])]

    def _losses(self, q, y, y_free, generator) -> dict[str, torch.Tensor]:
        x0 = torch.randn(q.shape, generator=generator)
        t = torch.rand(len(q), 1, generator=generator)
        velocity = velocity_at(self.nets["velocity"], (1.0 - t) * x0 + t * q, y, t)
        match = (velocity - (q - x0)).pow(2).sum(dim=1).mean()
        residual = torch.zeros(())
        if self.residual_fn is not None and self.config["residual_weight"] > 0:
            y_pen = y_free[: max(1, round(self.config["penalty_fraction"] * len(y_free)))]
            with torch.no_grad():
                x = self._before_last(y_pen, generator)
            residual = self.penalty(self._last(x, y_pen), y_pen).mean()
        return {"loss": match + self.config["residual_weight"] * residual, "match": match, "residual": residual}
