"""Conditional VAE (paper eq. 1): beta-weighted ELBO; at sampling time z ~ N(0, I) through the decoder.

Beyond the paper, the decoder is trained to be accurate: ``residual_weight`` weighs the
constraint residual (in tolerances, pseudo-Huber, via torch forward kinematics) of decoded
prior samples at conditions drawn across the trained range, ``recon_residual_weight`` that
of the reconstructions (so the decoder is accurate where the data is, not only near z = 0).
"""

from __future__ import annotations

import torch

from manifoldgen.models.adam import Adam
from manifoldgen.models.base import SingleLossSampler, mlp

# the posterior's log-variance is kept here: beyond it exp() overflows float32 (an infinite KL and reconstruction,
# seen on centauro's 39 coordinates at the defaults) or the variance is below any joint's resolution
LOGVAR_RANGE = (-30.0, 20.0)


class CVAE(SingleLossSampler):
    """Encoder q(z | q, y), decoder q = D(z, y); reconstruction is squared error in normalised units."""

    name = "cvae"
    defaults = {"latent": 3, "hidden": [128, 128], "beta": 0.1, "lr": 1e-3, "batch": 256,
                "epochs": 60, "patience": 15, "residual_weight": 0.1, "recon_residual_weight": 0.1}

    def _build(self) -> None:
        c = self.config
        self.nets["encoder"] = mlp(self.d + self.k, c["hidden"], 2 * c["latent"])
        self.nets["decoder"] = mlp(c["latent"] + self.k, c["hidden"], self.d)

    def _decode(self, z: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return self.nets["decoder"](torch.cat([z, y], dim=1))

    def _generate(self, y, generator):
        return self._decode(torch.randn(len(y), self.config["latent"], generator=generator), y)

    def _sampling_net(self):
        return self.nets["decoder"], "normal"

    def _optimizers(self):
        return [Adam(self.nets.parameters(), lr=self.config["lr"])]

    def _encode(self, q: torch.Tensor, y: torch.Tensor, generator: torch.Generator | None,
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Posterior mean, log-variance and a reparametrised sample, each (B, latent)."""
        mu, logvar = self.nets["encoder"](torch.cat([q, y], dim=1)).chunk(2, dim=1)
        logvar = logvar.clamp(*LOGVAR_RANGE)
        return mu, logvar, mu + torch.exp(0.5 * logvar) * torch.randn(mu.shape, generator=generator)

    def _losses(self, q, y, y_free, generator) -> dict[str, torch.Tensor]:
        mu, logvar, z = self._encode(q, y, generator)
        decoded = self._decode(z, y)
        recon = (decoded - q).pow(2).sum(dim=1).mean()
        kl = 0.5 * (mu.pow(2) + logvar.exp() - 1.0 - logvar).sum(dim=1).mean()
        rows = self.penalty(torch.cat([self._generate(y_free, generator), decoded]), torch.cat([y_free, y]))
        residual, recon_residual = rows[:len(y_free)].mean(), rows[len(y_free):].mean()
        total = (recon + self.config["beta"] * kl + self.config["residual_weight"] * residual
                 + self.config["recon_residual_weight"] * recon_residual)
        return {"loss": total, "recon": recon, "kl": kl, "residual": residual}
