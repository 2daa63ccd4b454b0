"""Conditional flow matching (rectified flow): a velocity field integrated from noise to configurations.

Training regresses a velocity MLP ``v(x_t, t, y)`` onto ``x1 - x0`` along straight interpolants
``x_t = (1 - t) x0 + t x1`` between ``x0 ~ N(0, I)`` and a normalised data row ``x1``; it has no
encoder or critic to collapse onto one IK branch. Sampling integrates ``dx/dt = v`` from noise with
``steps`` fixed Heun steps. Beyond the plain objective, ``residual_weight`` weighs the constraint residual
of the one-step endpoint estimate ``x1_hat = x_t + (1 - t) v``, each row weighted by ``t``.
"""

from __future__ import annotations

import torch

from manifoldgen.models.base import SingleLossSampler, mlp


class ConditionalFlowMatching(SingleLossSampler):
    """Velocity MLP on ``[x_t, y, t]``; samples by ``steps`` Heun steps of the ODE from t = 0 to 1."""

    name = "cfm"
    defaults = {"hidden": [256, 256, 256], "steps": 8, "lr": 1e-3, "batch": 256, "epochs": 60, "patience": 15,
                "residual_weight": 0.1}

    def _build(self) -> None:
        self.nets["velocity"] = mlp(self.d + self.k + 1, self.config["hidden"], self.d)

    def _velocity(self, x: torch.Tensor, t: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """v (B, d) at states x (B, d), times t (B, 1), conditions y (B, k)."""
        return self.nets["velocity"](torch.cat([x, y, t], dim=1))

    def _generate(self, y, generator):
        x = torch.randn(len(y), self.d, generator=generator)
        h = 1.0 / self.config["steps"]
        for i in range(self.config["steps"]):
            t = torch.full((len(y), 1), i * h)
            v = self._velocity(x, t, y)
            v_next = self._velocity(x + h * v, t + h, y)
            x = x + 0.5 * h * (v + v_next)
        return x

    def _sampling_net(self):
        return self.nets["velocity"], "normal"

    def _integration_steps(self) -> int:
        return int(self.config["steps"])

    def _optimizers(self):
        return [torch.optim.Adam(self.nets.parameters(), lr=self.config["lr"])]

    def _losses(self, q, y, y_free, generator) -> dict[str, torch.Tensor]:
        x0 = torch.randn(q.shape, generator=generator)
        t = torch.rand(len(q), 1, generator=generator)
        xt = (1.0 - t) * x0 + t * q
        v = self._velocity(xt, t, y)
        match = (v - (q - x0)).pow(2).sum(dim=1).mean()
        residual = self.penalty(xt + (1.0 - t) * v, y, weight=t.squeeze(1))
        return {"loss": match + self.config["residual_weight"] * residual, "match": match, "residual": residual}
