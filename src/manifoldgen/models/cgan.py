"""The paper's conditional GAN (eq. 3, z uniform) and the GAN machinery WGAN-GP shares.

GANs have no likelihood to early-stop on; their validation score is the sliced Wasserstein
distance between generated and held-out rows (normalised units), which punishes mode collapse.
Beyond the paper, ``residual_weight > 0`` adds the generator's mean constraint residual.
"""

from __future__ import annotations

from abc import abstractmethod

import torch
import torch.nn.functional as F

from manifoldgen.models.adam import Adam
from manifoldgen.models.base import ConditionalSampler, mlp


def sliced_wasserstein(a: torch.Tensor, b: torch.Tensor, generator: torch.Generator, projections: int = 64,
                       ) -> torch.Tensor:
    """Sliced 1-Wasserstein distance between equal-size point sets a, b (N, D)."""
    directions = torch.randn(a.shape[1], projections, generator=generator)
    directions = directions / directions.norm(dim=0, keepdim=True)
    pa, _ = torch.sort(a @ directions, dim=0)
    pb, _ = torch.sort(b @ directions, dim=0)
    return (pa - pb).abs().mean()


class _GAN(ConditionalSampler):
    """Generator G(z, y) and critic D(q, y); subclasses choose the noise and the losses."""

    def _build(self) -> None:
        c = self.config
        self.nets["generator"] = mlp(c["latent"] + self.k, c["hidden"], self.d)
        self.nets["critic"] = mlp(self.d + self.k, c["critic_hidden"], 1, torch.nn.LeakyReLU)

    latent_law: str  # "normal" or "uniform", as _noise draws (see ConditionalSampler._sampling_net)

    @abstractmethod
    def _noise(self, count: int, generator: torch.Generator | None) -> torch.Tensor:
        """Latent noise (count, latent)."""

    def _generate(self, y, generator):
        return self.nets["generator"](torch.cat([self._noise(len(y), generator), y], dim=1))

    def _sampling_net(self):
        return self.nets["generator"], self.latent_law

    def _critic(self, q: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return self.nets["critic"](torch.cat([q, y], dim=1)).squeeze(1)

    def _optimizers(self):
        c = self.config
        betas = (c["beta1"], 0.9)
        return [Adam(self.nets["generator"].parameters(), lr=c["lr"], betas=betas),
                Adam(self.nets["critic"].parameters(), lr=c["lr"], betas=betas)]

    @abstractmethod
    def _critic_loss(self, real: torch.Tensor, fake: torch.Tensor, y: torch.Tensor,
                     generator: torch.Generator) -> torch.Tensor:
        """Critic loss on real and generated normalised rows at conditions y."""

    @abstractmethod
    def _generator_loss(self, fake_score: torch.Tensor) -> torch.Tensor:
        """Generator adversarial loss from the critic's scores of generated rows."""

    def _train_step(self, q, y, y_free, optimizers, generator):
        g_opt, d_opt = optimizers
        self.nets.train()
        d_loss = torch.zeros(())
        for _ in range(self.config["critic_steps"]):
            with torch.no_grad():
                fake = self._generate(y, generator)
            d_loss = self._critic_loss(q, fake, y, generator)
            d_opt.zero_grad()
            d_loss.backward()
            d_opt.step()
        g_adv = self._generator_loss(self._critic(self._generate(y, generator), y))
        residual = self.penalty(self._generate(y_free, generator), y_free).mean()
        g_loss = g_adv + self.config["residual_weight"] * residual
        g_opt.zero_grad()
        g_loss.backward()
        g_opt.step()
        return {"critic": float(d_loss.detach()), "generator": float(g_adv.detach()), "residual": float(residual.detach())}

    def _validation_loss(self, q, y, generator):
        self.nets.eval()
        with torch.no_grad():
            fake = self._generate(y, generator)
            return float(sliced_wasserstein(torch.cat([q, y], 1), torch.cat([fake, y], 1), generator))


class CGAN(_GAN):
    """The paper's conditional GAN (eq. 3): binary cross-entropy, z ~ U(-1, 1)."""

    name = "cgan"
    latent_law = "uniform"
    defaults = {"latent": 8, "hidden": [128, 128], "critic_hidden": [128, 128], "lr": 2e-4, "beta1": 0.5,
                "batch": 256, "critic_steps": 1, "epochs": 40, "patience": 15, "residual_weight": 0.5}

    def _noise(self, count, generator):
        return torch.rand(count, self.config["latent"], generator=generator) * 2.0 - 1.0

    def _critic_loss(self, real, fake, y, generator):
        real_score, fake_score = self._critic(real, y), self._critic(fake, y)
        return (F.binary_cross_entropy_with_logits(real_score, torch.ones_like(real_score))
                + F.binary_cross_entropy_with_logits(fake_score, torch.zeros_like(fake_score)))

    def _generator_loss(self, fake_score):
        return F.binary_cross_entropy_with_logits(fake_score, torch.ones_like(fake_score))
