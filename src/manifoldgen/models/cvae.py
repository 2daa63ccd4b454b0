"""Conditional VAE (paper eq. 1): beta-weighted ELBO; at sampling time latent rows through the decoder.

Beyond the paper, the decoder is trained to be accurate: ``residual_weight`` weighs the
constraint residual (in tolerances, pseudo-Huber, via torch forward kinematics) of decoded
prior samples at conditions drawn across the trained range, ``recon_residual_weight`` that
of the reconstructions (so the decoder is accurate where the data is, not only near z = 0).

Beyond the paper too, the latent rows come from a learned prior: with ``prior_steps`` > 0 a small velocity
field ``v(z_t, y, t)`` (``prior_hidden``) carries N(0, I) noise to the encoder's posterior samples, trained by
flow matching beside the ELBO (on detached posterior samples, so it leaves the encoder and decoder as they are)
and integrated as :mod:`manifoldgen.models.cfm` integrates its rows. The encoder spreads the data wider than
N(0, I) in places and leaves holes in others; N(0, I) noise through the decoder then misses parts of the manifold
(panda pose: recall 0.43 without the prior, 0.66 with it, at the same accuracy). ``prior_steps = 0`` samples
N(0, I), as the paper.
The residual penalty stays on decoded N(0, I) noise and on the reconstructions, which lie where the prior samples.

The decoder must land within tolerance where a velocity field need not, so where :func:`width_for` gives at
most :data:`DEEP_WIDTH` it has three hidden layers that wide; a larger robot keeps two of the others' width (three
of 384 made g1's `train` too slow for a whole-body pipeline's three minutes). The encoder only has to place rows
in the latent space: on those smaller robots two layers of 64 (``encoder_hidden``) train 13-22 % faster, with
accuracy and recall up or down by at most 0.12; on whole-body robots so narrow an encoder stopped training early
with recall near 0, so there it keeps the decoder's layers. On a dataset of at least :data:`DECAY_BATCHES`
batches (every default collection) the rate decays along a cosine over 40 epochs (:data:`DECAYED_EPOCHS`) instead of
staying constant for 60: a third less training and more raw samples within tolerance on the arms, recall within
0.05, though the PR2's closed chain loses half its CVAE's recall (flow matching plans there). On fewer rows
a decaying rate left the constraint residual undertrained (1,000 rows: 17 % raw within tolerance against
92 %), so they keep 60 epochs at a constant rate. The figures, with their commands: docs/benchmarks.md,
"Learned samplers".
"""

from __future__ import annotations

import torch

from manifoldgen.models.adam import Adam
from manifoldgen.models.base import SingleLossSampler, integrate, mlp, velocity_at, width_for

# the posterior's log-variance is kept here: beyond it exp() overflows float32 (an infinite KL and reconstruction,
# seen on centauro's 39 coordinates at the defaults) or the variance is below any joint's resolution
LOGVAR_RANGE = (-30.0, 20.0)
DEEP_WIDTH = 256  # the hidden width of a robot small enough for three layers (see the module's docstring)
DECAY_BATCHES = 25  # batches per epoch from which the rate decays (6,400 rows at the default batch; docstring)
DECAYED_EPOCHS = 40  # the epochs a decaying rate trains: a third fewer, as accurate (see the module's docstring)


class CVAE(SingleLossSampler):
    """Encoder q(z | q, y), decoder q = D(z, y); reconstruction is squared error in normalised units."""

    name = "cvae"
    defaults = {"latent": 3, "hidden": [256, 256, 256], "encoder_hidden": [64, 64], "beta": 0.1, "lr": 1e-3,
                "lr_schedule": "constant", "batch": 256, "epochs": 60, "patience": 15, "residual_weight": 0.1,
                "recon_residual_weight": 0.1, "prior_steps": 4, "prior_hidden": [64, 64]}

    @classmethod
    def written_before(cls, config: dict) -> dict:
        """A file from before the learned prior sampled N(0, I); one from before ``encoder_hidden`` encoded
        through the decoder's ``hidden`` layers."""
        return {"prior_steps": 0, "encoder_hidden": config.get("hidden", cls.defaults["hidden"]), **config}

    def _build(self) -> None:
        c = self.config
        self.nets["encoder"] = mlp(self.d + self.k, c["encoder_hidden"], 2 * c["latent"])
        self.nets["decoder"] = mlp(c["latent"] + self.k, c["hidden"], self.d)
        if c["prior_steps"]:
            self.nets["prior"] = mlp(c["latent"] + self.k + 1, c["prior_hidden"], c["latent"])

    def size_for(self, joints: int, dimension: int, rows: int) -> None:
        """As every model (:meth:`ConditionalSampler.size_for`), then the layers not given: where :func:`width_for`
        ``joints`` is at most :data:`DEEP_WIDTH`, a decoder of three such layers and the default small encoder;
        else both two of :func:`width_for`. Where ``rows`` make at least :data:`DECAY_BATCHES` batches and no
        ``lr_schedule`` is given, the rate decays along a cosine, over :data:`DECAYED_EPOCHS` unless ``epochs``
        is given."""
        super().size_for(joints, dimension, rows)
        if "lr_schedule" not in self.given and rows // int(self.config["batch"]) >= DECAY_BATCHES:
            self.config["lr_schedule"] = "cosine"
            if "epochs" not in self.given:
                self.config["epochs"] = DECAYED_EPOCHS
        width = width_for(joints)
        if "hidden" not in self.given:
            self.config["hidden"] = [DEEP_WIDTH] * 3 if width <= DEEP_WIDTH else [width] * 2
        if "encoder_hidden" not in self.given and width > DEEP_WIDTH:
            self.config["encoder_hidden"] = [width] * 2

    def _decode(self, z: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return self.nets["decoder"](torch.cat([z, y], dim=1))

    def _latent(self, y: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
        """Latent rows (B, latent) at normalised conditions y (B, k): N(0, I) noise, carried by the prior's flow."""
        z = torch.randn(len(y), self.config["latent"], generator=generator)
        return integrate(self.nets["prior"], z, y, self.config["prior_steps"]) if "prior" in self.nets else z

    def _generate(self, y, generator):
        return self._decode(self._latent(y, generator), y)

    def _sampling_net(self):
        return self.nets["decoder"], "normal"

    def _prior_net(self):
        return (self.nets["prior"], int(self.config["prior_steps"])) if "prior" in self.nets else None

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
        z_free = torch.randn(len(y_free), self.config["latent"], generator=generator)
        rows = self.penalty(torch.cat([self._decode(z_free, y_free), decoded]), torch.cat([y_free, y]))
        residual, recon_residual = rows[:len(y_free)].mean(), rows[len(y_free):].mean()
        total = (recon + self.config["beta"] * kl + self.config["residual_weight"] * residual
                 + self.config["recon_residual_weight"] * recon_residual)
        losses = {"recon": recon, "kl": kl, "residual": residual}
        if "prior" in self.nets:  # flow matching from N(0, I) to the posterior samples, which it does not move
            target, z0 = z.detach(), torch.randn(z.shape, generator=generator)
            t = torch.rand(len(z), 1, generator=generator)
            velocity = velocity_at(self.nets["prior"], (1.0 - t) * z0 + t * target, y, t)
            losses["prior"] = (velocity - (target - z0)).pow(2).sum(dim=1).mean()
            total = total + losses["prior"]
        return {"loss": total, **losses}
