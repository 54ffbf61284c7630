"""Adversarial losses of the texture GAN: the loss object owns the lazy regularisation schedule.

Two discriminators judge the generator: ``d_field`` sees psi renders, ``d_proxy`` the per-face
colour renders. Losses (StyleGAN2):
    G main:  softplus(-D_field(fake)) + proxy_weight * softplus(-D_proxy(proxy))    (non-saturating)
    G div:   diversity_weight * max(0, diversity_target - d), d the mode-seeking ratio (below), in G main
             from iteration ``diversity_start`` on, every ``diversity_interval`` steps, scaled by it
    G colour: colour_weight * sum over CIELAB channels of ((mean - photo mean)^2 + (std - photo std)^2) / photo std^2,
             the moments of object pixels in the field renders, running means over recent steps (below), in G main
    G reg:   path-length regularisation on psi renders, every ``pl_interval`` steps, scaled by it, on
             the first batch / ``pl_batch_shrink`` shapes of the batch (StyleGAN2's default of 2)
    D main:  softplus(D(fake)) + softplus(-D(real)) for both discriminators
    D reg:   R1 = gamma/2 |grad_x D(real)|^2 for both, every ``r1_interval`` steps, scaled by it

Every image a discriminator sees, real or fake and in every phase, first goes through ``augment``
(differentiable, :mod:`mesh2tex.losses.augment`). Fakes and reals go through the discriminators in
separate calls: the minibatch standard deviation layer must see groups of fakes only or reals only,
or a collapsed generator (every latent the same texture) would look as diverse as the photos.

The diversity term is the mode-seeking regulariser of MSGAN / DSGAN (Mao et al. 2019, Yang et al.
2019) on the cheap proxy path: the same shapes, views, backgrounds and lights rendered from a second
latent z', d = mean |proxy(z) - proxy(z')| over object pixels and channels / mean |z - z'|. It pushes
different latents apart until d reaches ``diversity_target`` and then leaves the generator alone.
It costs a second synthesis forward and backward; applied lazily (``diversity_interval`` > 1, its
gain scaled by the interval as R1's is) it costs that much less. Until ``diversity_start`` it draws
no second latent at all, so a run that starts the term late is, step for step, the run without the
term resumed with it (the chair model was trained that way, in two runs).

The colour term matches the first two moments of the generator's object colours (CIELAB, lit, as the
discriminator sees them) to the photo collection's (:meth:`GanLoss.set_colour_target`). Without it
a long run's generator swings its whole palette from a few hundred steps to the next, and the
renders of its EMA stay darker and duller than the photos: on the 56-chair world, matching those
moments after the fact would take the held-out object SWD from 157 to 100 (docs/results/gan.md, *The
palette swings*). The moments are running means (``colour_decay`` the weight of each step's batch) so that
the term corrects the generator's global bias: a batch of two latents is not pushed towards the
photos' mean colour, which would shrink every sample towards it. Its value is the running
moments'; its gradient flows through this batch's.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import Callable

import torch
import torch.nn.functional as F
from kornia.color import rgb_to_lab
from torch import nn

from mesh2tex.checks import check_shape
from mesh2tex.config import check_fields
from mesh2tex.nn.batch import MeshBatch, collate_shapes
from mesh2tex.nn.render_texture import SurfaceSamples, render_field_views, render_proxy_views
from mesh2tex.render import Lights, RenderSettings

PHASES = ("Gmain", "Greg", "Dmain", "Dreg")


@dataclass
class GanLossConfig:
    r1_gamma: float = 1.0  # R1 weight gamma (0 disables)
    r1_interval: int = 16  # lazy R1: every this many iterations
    pl_weight: float = 2.0  # path-length regularisation weight (0 disables)
    pl_interval: int = 4  # lazy path-length regularisation: every this many iterations
    pl_decay: float = 0.01  # running-mean decay of the path lengths
    pl_batch_shrink: int = 2  # the path-length phase renders batch // this many shapes (at least 1), as StyleGAN2 does
    proxy_weight: float = 1.0  # weight of the proxy (per-face colour) adversarial loss
    diversity_weight: float = 1.0  # mode-seeking term on the proxy renders of two latents (0 disables)
    # the term stops pushing once d (mean abs proxy difference / mean abs latent difference) reaches it
    diversity_target: float = 0.3
    diversity_start: int = 0  # the first iteration (0-based) with the term
    diversity_interval: int = 1  # lazy mode seeking: every this many iterations from diversity_start, scaled by it
    # colour-moment term: the object colours' CIELAB mean and std against the photos' (0 disables)
    colour_weight: float = 0.0
    colour_decay: float = 0.05  # the weight of each step's batch in the running moments

    def __post_init__(self):
        check_fields(
            self,
            at_least={
                "r1_gamma": 0,
                "pl_weight": 0,
                "proxy_weight": 0,
                "r1_interval": 1,
                "pl_interval": 1,
                "pl_batch_shrink": 1,
                "diversity_weight": 0,
                "diversity_target": 0,
                "diversity_start": 0,
                "diversity_interval": 1,
                "colour_weight": 0,
            },
            between={"pl_decay": (0.0, 1.0), "colour_decay": (0.0, 1.0)},
        )


@dataclass
class GanScene:
    """What one iteration's fakes are rendered into: the shapes, each seen by K views, their
    backgrounds and lights (every phase of the iteration renders the same scene).

    shapes: the B prepared shapes of the batch; batch: them collated on the device; mvp (N, 4, 4),
    N = B K, view k of shape s at s K + k; samples: the finest level rasterized at ``side`` =
    ``render.raster_side``; background (N, 3) in [-1, 1]; lights: one per view, or None (unlit);
    render: the fakes' settings, rasterized ``render.supersample`` times larger and box-filtered down to
    the photos' resolution.
    """

    shapes: list
    batch: MeshBatch
    mvp: torch.Tensor
    samples: SurfaceSamples
    background: torch.Tensor
    lights: Lights | None
    render: RenderSettings

    @property
    def side(self) -> int:
        return int(self.samples.triangle_id.shape[-1])

    def down(self, images: torch.Tensor) -> torch.Tensor:
        """Renders at ``side`` -> the photos' resolution (box filter)."""
        return self.render.down(images)

    @property
    def object_mask(self) -> torch.Tensor:
        """(N, 1, R, R) object coverage of the views at the photos' resolution."""
        return self.down(self.samples.mask.unsqueeze(1).float())

    def first(self, count: int) -> "GanScene":
        """The scene of the first ``count`` shapes and their views (the path-length phase's smaller batch)."""
        if count == len(self.shapes):
            return self
        # their views come first, and their triangle ids are the same
        m = count * (self.mvp.shape[0] // len(self.shapes))
        lights = None if self.lights is None else Lights(self.lights.direction[:m], self.lights.ambient[:m])
        return GanScene(
            self.shapes[:count],
            collate_shapes(self.shapes[:count]).to(self.mvp.device),
            self.mvp[:m],
            SurfaceSamples(self.samples.triangle_id[:m], self.samples.bary[:m]),
            self.background[:m],
            lights,
            self.render,
        )


def mode_seeking_ratio(
    proxy_a: torch.Tensor, proxy_b: torch.Tensor, mask: torch.Tensor, z_a: torch.Tensor, z_b: torch.Tensor
) -> torch.Tensor:
    """d = mean |proxy_a - proxy_b| over object pixels and channels / mean |z_a - z_b|: a scalar, 0 for a collapsed
    generator.

    proxy_a, proxy_b: (N, 3, H, W) renders of latents z_a, z_b (B, z_dim) of the same views; mask (N, 1, H, W).
    """
    sizes = check_shape(proxy_a, "mode_seeking_ratio: proxy_a", ("N", 3, "H", "W"), dtype="float")
    check_shape(proxy_b, "mode_seeking_ratio: proxy_b", ("N", 3, "H", "W"), sizes=sizes, dtype="float")
    check_shape(mask, "mode_seeking_ratio: mask", ("N", 1, "H", "W"), sizes=sizes)
    check_shape(z_a, "mode_seeking_ratio: z_a", ("B", "Z"), sizes=sizes, dtype="float")
    check_shape(z_b, "mode_seeking_ratio: z_b", ("B", "Z"), sizes=sizes, dtype="float")
    image_distance = ((proxy_a - proxy_b).abs().float() * mask).sum() / (3 * mask.sum()).clamp(min=1.0)
    return image_distance / (z_a - z_b).abs().mean().clamp(min=1e-8)


def object_lab_moments(images: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The CIELAB mean and mean square of object pixels, pooled over the batch, differentiable.

    images (N, 3, H, W) in [-1, 1]; mask (N, 1, H, W) (object > 0.5) -> (mean (3,), mean square (3,)) float32."""
    _check_images(images, mask, "object_lab_moments", "images", "mask")
    lab = rgb_to_lab(((images.float() + 1) / 2).clamp(0, 1))  # (N, 3, H, W)
    weight = (mask > 0.5).float()
    count = weight.sum().clamp(min=1.0)
    mean = (lab * weight).sum(dim=(0, 2, 3)) / count
    return mean, (lab.square() * weight).sum(dim=(0, 2, 3)) / count


def _check_images(images: torch.Tensor, masks: torch.Tensor, function: str, name: str, mask_name: str) -> None:
    """images (N, 3, H, W) float and their masks (N, 1, H, W), named in the message as ``function: name``."""
    sizes = check_shape(images, f"{function}: {name}", ("N", 3, "H", "W"), dtype="float")
    check_shape(masks, f"{function}: {mask_name}", ("N", 1, "H", "W"), sizes=sizes)


class GanLoss:
    """Runs the generator and both discriminators for one phase at a time on an iteration's
    :class:`GanScene` and back-propagates its loss (as stylegan2-ada's loss runs G and D itself); keeps
    the running path-length mean and colour moments.

    ``autocast``: a context factory for the main phases (mixed precision on CUDA); the
    regularisation phases always run in float32.
    """

    def __init__(
        self,
        cfg: GanLossConfig,
        generator: nn.Module | None = None,
        d_field: nn.Module | None = None,
        d_proxy: nn.Module | None = None,
        autocast: Callable = contextlib.nullcontext,
        augment: Callable[[torch.Tensor], torch.Tensor] | None = None,
    ):
        self.cfg, self.generator, self.d_field, self.d_proxy, self.autocast = cfg, generator, d_field, d_proxy, autocast
        self.augment = augment or (lambda x: x)
        self.pl_mean = torch.zeros([])
        self.colour_target: tuple[torch.Tensor, torch.Tensor] | None = None  # the photos' CIELAB (mean (3,), std (3,))
        # (2, 3) running mean and mean square of the fakes' object colours
        self.colour_running: torch.Tensor | None = None

    def set_colour_target(self, photos: torch.Tensor, masks: torch.Tensor) -> None:
        """The colour term's target: the CIELAB moments of the photos' object pixels.
        photos (N, 3, H, W) in [-1, 1], masks (N, 1, H, W)."""
        _check_images(photos, masks, "GanLoss.set_colour_target", "photos", "masks")
        mean, square = object_lab_moments(photos, masks)
        self.colour_target = (mean, (square - mean.square()).clamp(min=1e-6).sqrt())

    def colour_loss(self, images: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """The colour-moment term (unweighted) of fakes ``images`` (N, 3, H, W) with object ``mask``
        (N, 1, H, W); updates the running moments. Its value is the running moments' distance to the
        target; its gradient is that of this batch's moments."""
        _check_images(images, mask, "GanLoss.colour_loss", "images", "mask")
        if self.colour_target is None:
            raise ValueError("GanLoss: colour_weight > 0 needs set_colour_target (the photos' moments)")
        batch = torch.stack(object_lab_moments(images, mask))  # (2, 3)
        previous = batch.detach() if self.colour_running is None else self.colour_running.to(batch.device)
        running = previous.lerp(batch.detach(), self.cfg.colour_decay)
        self.colour_running = running
        moments = running + (batch - batch.detach())  # the running value, this batch's gradient
        mean, std = moments[0], (moments[1] - moments[0].square()).clamp(min=1e-6).sqrt()
        target_mean, target_std = (t.to(images.device) for t in self.colour_target)
        return (((mean - target_mean).square() + (std - target_std).square()) / target_std.square()).sum()

    def phases(self, iteration: int) -> list[tuple[str, float]]:
        """(phase, gain) to run at ``iteration`` (0-based): main phases always, regularisers lazily."""
        out = [("Gmain", 1.0)]
        if self.cfg.pl_weight > 0 and iteration % self.cfg.pl_interval == 0:
            out.append(("Greg", float(self.cfg.pl_interval)))
        out.append(("Dmain", 1.0))
        if self.cfg.r1_gamma > 0 and iteration % self.cfg.r1_interval == 0:
            out.append(("Dreg", float(self.cfg.r1_interval)))
        return out

    def path_length_shapes(self, batch: int) -> int:
        """How many of a batch's ``batch`` shapes (and their latents) the path-length phase renders."""
        return max(1, batch // self.cfg.pl_batch_shrink)

    def diversity_gain(self, iteration: int) -> float:
        """The diversity term's gain in G main at ``iteration`` (0-based): 0 when it does not run."""
        cfg = self.cfg
        if (
            cfg.diversity_weight == 0
            or iteration < cfg.diversity_start
            or (iteration - cfg.diversity_start) % cfg.diversity_interval
        ):
            return 0.0
        return float(cfg.diversity_interval)

    def fakes(
        self, z: torch.Tensor, scene: GanScene, update_w_avg: bool = False
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, list]:
        """The generator's renders of latents z (B, z_dim), one per shape of ``scene``: (psi images (N, 3, R, R),
        proxy images (N, 3, R, R), ws (B, num_ws, w_dim), the encoder's output, which :meth:`proxy_fakes` reuses)."""
        g = self.generator
        ws = g.mapping(z, update_w_avg=update_w_avg)
        encoded = g.encoder(scene.batch)
        out = render_field_views(
            g,
            scene.batch,
            ws,
            scene.mvp,
            (scene.side, scene.side),
            scene.background,
            proxy=True,
            samples=scene.samples,
            lights=scene.lights,
            encoded=encoded,
        )
        return scene.down(out.images), scene.down(out.proxy), ws, encoded

    def proxy_fakes(self, z: torch.Tensor, scene: GanScene, encoded: list) -> torch.Tensor:
        """The proxy renders (N, 3, R, R) of other latents z on the same scene (the diversity term's second latent)."""
        texture = self.generator.synthesize(scene.batch, self.generator.mapping(z), encoded=encoded)
        return scene.down(render_proxy_views(texture, scene.batch, scene.samples, scene.background, scene.lights))

    def accumulate_gradients(
        self,
        phase: str,
        scene: GanScene,
        z: torch.Tensor,
        real: torch.Tensor,
        gain: float = 1.0,
        diversity_gain: float = 1.0,
    ) -> dict[str, torch.Tensor]:
        """Back-propagate the loss of ``phase`` on ``scene`` (scaled by ``gain``); returns detached scalars to log.

        z: (B, z_dim) latents, one per shape of the scene (the path-length phase takes the first
        :meth:`path_length_shapes` of them and their shapes); real: (N, 3, H, W) real images in [-1, 1];
        diversity_gain: the diversity term's gain in G main (:meth:`diversity_gain` of the iteration).
        """
        check_shape(z, "GanLoss.accumulate_gradients: z", ("B", None), ("B",), dtype="float")
        check_shape(real, "GanLoss.accumulate_gradients: real", (None, 3, None, None), dtype="float")
        logs: dict[str, torch.Tensor] = {}
        if phase == "Gmain":
            with self.autocast():
                images, proxy, _, encoded = self.fakes(z, scene, update_w_avg=True)
                loss = F.softplus(-self.d_field(self.augment(images))).mean()
                logs["loss_g_field"] = loss.detach()
                if proxy is not None and self.cfg.proxy_weight > 0:
                    loss_proxy = F.softplus(-self.d_proxy(self.augment(proxy))).mean()
                    logs["loss_g_proxy"] = loss_proxy.detach()
                    loss = loss + self.cfg.proxy_weight * loss_proxy
                if self.cfg.diversity_weight > 0 and diversity_gain > 0:
                    z_other = torch.randn_like(z)
                    ratio = mode_seeking_ratio(
                        proxy, self.proxy_fakes(z_other, scene, encoded), scene.object_mask, z, z_other
                    )
                    logs["mode_seeking"] = ratio.detach()
                    loss = loss + diversity_gain * self.cfg.diversity_weight * F.relu(self.cfg.diversity_target - ratio)
            if self.cfg.colour_weight > 0:
                colour = self.colour_loss(images, scene.object_mask)
                logs["colour_moments"] = colour.detach()
                loss = loss + self.cfg.colour_weight * colour
            (loss * gain).backward()
        elif phase == "Greg":  # on the first batch / pl_batch_shrink shapes (StyleGAN2's smaller path-length batch)
            count = self.path_length_shapes(z.shape[0])
            images, _, ws, _ = self.fakes(z[:count], scene.first(count))
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
                images, proxy, _, _ = self.fakes(z, scene)
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

    def _d_main(
        self, d: nn.Module, fake: torch.Tensor, real: torch.Tensor, logs: dict | None = None, name: str = ""
    ) -> torch.Tensor:
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
        state = {"pl_mean": self.pl_mean.detach().cpu().reshape([])}
        if self.colour_running is not None:
            state["colour_running"] = self.colour_running.detach().cpu()
        return state

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        self.pl_mean = state["pl_mean"].clone().reshape([])
        # absent before the term
        self.colour_running = state["colour_running"].clone() if "colour_running" in state else None
