"""Wasserstein GAN with gradient penalty: a conditional GAN that does not mode-collapse."""

from __future__ import annotations

import torch

from manifoldgen.models.cgan import _GAN


class WGANGP(_GAN):
    """Wasserstein GAN with gradient penalty (Gulrajani et al. 2017), z ~ N(0, I)."""

    name = "wgan"
    latent_law = "normal"
    defaults = {"latent": 8, "hidden": [128, 128], "critic_hidden": [128, 128], "lr": 2e-4, "beta1": 0.5,
                "batch": 256, "critic_steps": 3, "gp": 1.0, "epochs": 40, "patience": 15,
                "residual_weight": 0.1}

    def _noise(self, count, generator):
        return torch.randn(count, self.config["latent"], generator=generator)

    def _critic_loss(self, real, fake, y, generator):
        alpha = torch.rand(len(real), 1, generator=generator)
        mixed = (alpha * real + (1 - alpha) * fake).requires_grad_(True)
        grad, = torch.autograd.grad(self._critic(mixed, y).sum(), mixed, create_graph=True)
        penalty = (grad.norm(dim=1) - 1.0).pow(2).mean()
        return self._critic(fake, y).mean() - self._critic(real, y).mean() + self.config["gp"] * penalty

    def _generator_loss(self, fake_score):
        return -fake_score.mean()
