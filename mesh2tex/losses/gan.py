"""Adversarial losses of the texture GAN: the loss object owns the lazy regularisation schedule.

Two discriminators judge the generator: ``d_field`` sees psi renders, ``d_proxy`` the per-face
colour renders. Losses (StyleGAN2):
    G main:  softplus(-D_field(fake)) + proxy_weight * softplus(-D_proxy(proxy))    (non-saturating)
    G reg:   path-length regularisation on psi renders, every ``pl_interval`` steps, scaled by it
    D main:  softplus(D(fake)) + softplus(-D(real)) for both discriminators
    D reg:   R1 = gamma/2 |grad_x D(real)|^2 for both, every ``r1_interval`` steps, scaled by it

Every image a discriminator sees, real or fake and in every phase, first goes through ``augment``
(differentiable, :mod:`mesh2tex.losses.augment`). Fakes and reals go through the discriminators in
separate calls: the minibatch standard deviation layer must see groups of fakes only or reals only,
or a collapsed generator (every latent the same texture) would look as diverse as the photos.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import Callable

import torch
import torch.nn.functional as F
from torch import nn

from mesh2tex.config import check_fields

PHASES = ("Gmain", "Greg", "Dmain", "Dreg")


@dataclass
class GanLossConfig:
    r1_gamma: float = 1.0  # R1 weight gamma (0 disables)
    r1_interval: int = 16  # lazy R1: every this many iterations
    pl_weight: float = 2.0  # path-length regularisation weight (0 disables)
    pl_interval: int = 4  # lazy path-length regularisation: every this many iterations
    pl_decay: float = 0.01  # running-mean decay of the path lengths
    proxy_weight: float = 1.0  # weight of the proxy (per-face colour) adversarial loss

    def __post_init__(self):
        check_fields(self, at_least={"r1_gamma": 0, "pl_weight": 0, "proxy_weight": 0, "r1_interval": 1, "pl_interval": 1},
                     between={"pl_decay": (0.0, 1.0)})


# generate(z) -> (psi images (N,3,H,W), proxy images (N,3,H,W) or None, ws (B,num_ws,w_dim))
GenerateFn = Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]]


class GanLoss:
    """Computes and back-propagates one phase at a time; keeps the running path-length mean.

    ``autocast``: a context factory for the main phases (mixed precision on CUDA); the
    regularisation phases always run in float32.
    """

    def __init__(self, cfg: GanLossConfig, d_field: nn.Module, d_proxy: nn.Module, autocast: Callable = contextlib.nullcontext,
                 augment: Callable[[torch.Tensor], torch.Tensor] | None = None):
        self.cfg, self.d_field, self.d_proxy, self.autocast = cfg, d_field, d_proxy, autocast
        self.augment = augment or (lambda x: x)
        self.pl_mean = torch.zeros([])

    def phases(self, iteration: int) -> list[tuple[str, float]]:
        """(phase, gain) to run at ``iteration`` (0-based): main phases always, regularisers lazily."""
        out = [("Gmain", 1.0)]
        if self.cfg.pl_weight > 0 and iteration % self.cfg.pl_interval == 0:
            out.append(("Greg", float(self.cfg.pl_interval)))
        out.append(("Dmain", 1.0))
        if self.cfg.r1_gamma > 0 and iteration % self.cfg.r1_interval == 0:
            out.append(("Dreg", float(self.cfg.r1_interval)))
        return out

    def accumulate_gradients(self, phase: str, generate: GenerateFn, z: torch.Tensor, real: torch.Tensor, gain: float = 1.0) -> dict[str, torch.Tensor]:
        """Back-propagate the loss of ``phase`` (scaled by ``gain``); returns detached scalars to log.

        z: (B, z_dim) latents, real: (N, 3, H, W) real images in [-1, 1].
        """
        logs: dict[str, torch.Tensor] = {}
        if phase == "Gmain":
            with self.autocast():
                images, proxy, _ = generate(z)
                loss = F.softplus(-self.d_field(self.augment(images))).mean()
                logs["loss_g_field"] = loss.detach()
                if proxy is not None and self.cfg.proxy_weight > 0:
                    loss_proxy = F.softplus(-self.d_proxy(self.augment(proxy))).mean()
                    logs["loss_g_proxy"] = loss_proxy.detach()
                    loss = loss + self.cfg.proxy_weight * loss_proxy
            (loss * gain).backward()
        elif phase == "Greg":
            images, _, ws = generate(z)
            h, w = images.shape[2], images.shape[3]
            noise = torch.randn_like(images) / math.sqrt(h * w)
            (grad,) = torch.autograd.grad((images * noise).sum(), ws, create_graph=True)
            lengths = grad.square().sum(2).mean(1).sqrt()  # (B,)
            self.pl_mean = self.pl_mean.to(lengths.device)
            pl_mean = self.pl_mean.lerp(lengths.mean().detach(), self.cfg.pl_decay)
            self.pl_mean = pl_mean.detach()
            penalty = (lengths - pl_mean).square().mean()
            (penalty * self.cfg.pl_weight * gain).backward()
            logs["pl_penalty"] = penalty.detach()
            logs["pl_mean"] = self.pl_mean.clone()
        elif phase == "Dmain":
            with torch.no_grad(), self.autocast():
                images, proxy, _ = generate(z)
            with self.autocast():
                loss = self._d_main(self.d_field, images, real, logs, "field")
                logs["loss_d_field"] = loss.detach()
                if proxy is not None and self.cfg.proxy_weight > 0:
                    loss_proxy = self._d_main(self.d_proxy, proxy, real, logs, "proxy")
                    logs["loss_d_proxy"] = loss_proxy.detach()
                    loss = loss + loss_proxy
            (loss * gain).backward()
        elif phase == "Dreg":
            total = 0.0
            for name, d in (("field", self.d_field), ("proxy", self.d_proxy)):
                if name == "proxy" and self.cfg.proxy_weight <= 0:
                    continue
                x = real.detach().float().requires_grad_(True)
                logits = d(self.augment(x))
                (grad,) = torch.autograd.grad(logits.sum(), x, create_graph=True)
                r1 = grad.square().sum(dim=[1, 2, 3]).mean()
                logs[f"r1_{name}"] = r1.detach()
                total = total + r1 * (self.cfg.r1_gamma / 2)
            (total * gain).backward()
        else:
            raise ValueError(f"unknown phase {phase!r}; expected one of {PHASES}")
        return logs

    def _d_main(self, d: nn.Module, fake: torch.Tensor, real: torch.Tensor, logs: dict | None = None, name: str = "") -> torch.Tensor:
        """softplus(D(fake)) + softplus(-D(real)), fakes and reals in separate calls (see the module docstring).

        Logs the mean logits ``score_fake_<name>``, ``score_real_<name>`` and ``sign_real_<name>``
        (the mean sign of the real logits: ADA's overfitting measure r_t) into ``logs`` when given."""
        fake_logits = d(self.augment(fake.detach()))
        real_logits = d(self.augment(real.to(fake.dtype)))
        if logs is not None:
            logs[f"score_fake_{name}"] = fake_logits.detach().float().mean()
            logs[f"score_real_{name}"] = real_logits.detach().float().mean()
            logs[f"sign_real_{name}"] = real_logits.detach().float().sign().mean()
        return F.softplus(fake_logits).mean() + F.softplus(-real_logits).mean()

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {"pl_mean": self.pl_mean.detach().cpu().reshape([])}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        self.pl_mean = state["pl_mean"].clone().reshape([])
