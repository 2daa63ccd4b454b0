"""Conditional normalizing flow (zuko neural spline flow with coupling layers).

Exact likelihood training; sampling pushes z ~ N(0, I) through the inverse transform,
using the caller's generator. Beyond the paper, ``residual_weight > 0`` adds the constraint
residual of reparametrised samples.
"""

from __future__ import annotations

import torch

from manifoldgen.errors import require
from manifoldgen.models.adam import Adam
from manifoldgen.models.base import SingleLossSampler


class ConditionalFlow(SingleLossSampler):
    """zuko NSF with ``passes=2`` (coupling: one pass both ways, fast sampling)."""

    name = "flow"
    defaults = {"transforms": 4, "hidden": [128, 128], "bins": 8, "lr": 1e-3, "batch": 512,
                "epochs": 30, "patience": 10, "residual_weight": 0.2}

    def _build(self) -> None:
        c = self.config
        zuko = require("zuko", "flow", "the flow model")
        self.nets["flow"] = zuko.flows.NSF(self.d, self.k, transforms=c["transforms"], bins=c["bins"],
                                           hidden_features=list(c["hidden"]), passes=2)

    def _generate(self, y, generator):
        z = torch.randn(len(y), self.d, generator=generator)
        return self.nets["flow"](y).transform.inv(z)

    def _optimizers(self):
        return [Adam(self.nets.parameters(), lr=self.config["lr"])]

    def _losses(self, q, y, y_free, generator) -> dict[str, torch.Tensor]:
        nll = -self.nets["flow"](y).log_prob(q).mean()
        residual = self.penalty(self._generate(y_free, generator), y_free).mean()
        return {"loss": nll + self.config["residual_weight"] * residual, "nll": nll, "residual": residual}
