"""The optimisation of a transfer: the latent, then the last synthesis blocks, against the photo's
style (Mesh2Tex Equation 2, NOC-guided patch pairs)."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import asdict, dataclass, field

import torch

from mesh2tex.checks import check_shape
from mesh2tex.errors import InputError
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.geometry.symmetry import mirror_axis
from mesh2tex.losses.style import (
    global_style_loss,
    lowpass_colour_loss,
    patch_style_loss,
    sample_patch_pairs,
    style_grams,
)
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.generator import TextureGenerator
from mesh2tex.nn.render_texture import rasterize_batch, render_field_views
from mesh2tex.progress import progress_bar
from mesh2tex.render import crop_square
from mesh2tex.texturing import mean_latent
from mesh2tex.transfer.config import TransferConfig
from mesh2tex.transfer.light import LightStart, PhotoLight, starting_light
from mesh2tex.transfer.photo import FramedView, Photo, check_query, check_view, mirror_query, view_at_pose


class PhotoLoss:
    """The transfer's losses of a render at the photo's pose (the view's crop) against the photo:
    ``w_glob`` times the global style loss, ``w_patch`` times the patch style loss over patch pairs
    (NOC-guided when ``cfg.use_noc`` and ``cfg.use_patches``) and ``w_colour`` times the low-pass
    colour loss, each as ``cfg`` turns it on. Used by :func:`transfer_texture` and by
    :func:`mesh2tex.transfer.automaton.fit_automaton`.

    Calling it with an image (1, 3, R, R) in [-1, 1] returns (total loss, {part: float}); the patch
    pairs are drawn from ``pick`` (default: its own generator, seeded with ``cfg.seed``). photo: image (1, 3, R, R),
    mask (1, 1, R, R); view: noc (R, R, 3), mask (1, 1, R, R); photo_noc (R, R, 3) or None.
    """

    def __init__(
        self,
        photo: Photo,
        view: FramedView,
        photo_noc: torch.Tensor | None,
        vgg,
        cfg: TransferConfig,
        device: torch.device,
    ):
        self.sizes = check_query(photo, view, photo_noc, "PhotoLoss")
        self.guided = cfg.use_noc and cfg.use_patches
        if self.guided and photo_noc is None:
            raise InputError("NOC-guided patches need the photo's NOC: give --noc-checkpoint, or --no-noc")
        self.vgg, self.cfg = vgg, cfg
        self.photo_image, self.photo_mask = photo.image.to(device), photo.mask.to(device)
        self.render_mask = view.mask.to(device)
        self.render_noc = view.noc.to(device)
        self.photo_noc = photo_noc.to(device) if photo_noc is not None else None
        with torch.no_grad():
            self.photo_grams = style_grams(vgg, self.photo_image, self.photo_mask, cfg.scales)
        self.pick = torch.Generator().manual_seed(cfg.seed)
        self.colour_sigma = cfg.colour_sigma * cfg.resolution

    def __call__(
        self, image: torch.Tensor, use_global: bool, pick: torch.Generator | None = None
    ) -> tuple[torch.Tensor, dict[str, float]]:
        check_shape(image, "PhotoLoss: image", (1, 3, "R", "R"), sizes=dict(self.sizes), dtype="float")
        cfg, vgg = self.cfg, self.vgg
        parts: dict[str, torch.Tensor] = {}
        if use_global:
            parts["global"] = cfg.w_glob * global_style_loss(
                vgg, image, self.render_mask, target_grams=self.photo_grams, scales=cfg.scales
            )
        if cfg.use_patches:
            pairs = sample_patch_pairs(
                self.photo_mask[0, 0],
                self.render_mask[0, 0],
                cfg.patches,
                self.photo_noc,
                self.render_noc,
                guided=self.guided,
                generator=self.pick if pick is None else pick,
            )
            parts["patch"] = cfg.w_patch * patch_style_loss(
                vgg, image, self.render_mask, self.photo_image, self.photo_mask, pairs, cfg.patch_size, cfg.patch_levels
            )
        if cfg.w_colour > 0:
            parts["colour"] = cfg.w_colour * lowpass_colour_loss(
                image, self.render_mask, self.photo_image, self.photo_mask, self.colour_sigma
            )
        total = sum(parts.values())
        return total, {k: float(v.detach()) for k, v in parts.items()}


@dataclass
class TransferResult:
    ws: torch.Tensor  # (1, num_ws, w_dim) the optimised latent
    # (1, 3, R, R) the final render at the pose, cropped, in [-1, 1] (lit by ``light`` when one was learnt)
    render: torch.Tensor
    losses: dict[str, list[float]] = field(default_factory=dict)  # per stage, one value per iteration
    seconds: dict[str, float] = field(default_factory=dict)  # per stage
    light: dict[str, float] | None = None  # the photo's light as used (PhotoLight.describe), None: unlit renders
    # where that light started (LightStart as a dict: search_light's find, or the prior's middle), None: unlit
    light_start: dict[str, float] | None = None
    # the axis ("x" or "z") normal to the mirror plane the photo was also read across (cfg.w_mirror), None when not
    mirror: str | None = None


def learns_light(cfg: TransferConfig, generator_lit: bool) -> bool:
    """Whether a transfer learns the photo's light: ``cfg.light`` 'learn', or 'auto' for a generator
    trained under the light prior (its colours are albedo)."""
    return cfg.light == "learn" or (cfg.light == "auto" and generator_lit)


def photo_light(
    photo: Photo, view: FramedView, batch, samples, cfg: TransferConfig, generator_lit: bool, known: LightStart | None
) -> PhotoLight | None:
    """The light a transfer renders under (None: unlit, :func:`learns_light`): started at ``known`` when the
    photo's light is known, else as ``cfg.light_start`` says, its ambient share at ``cfg.light_ambient`` when
    that is positive. photo: image (1, 3, R, R), mask (1, 1, R, R); samples: the mesh rasterized at ``view``."""
    if not learns_light(cfg, generator_lit):
        return None
    ambient = cfg.light_ambient if cfg.light_ambient > 0 else None
    return starting_light(photo, view, batch, samples, known or cfg.light_start, ambient)


def transfer_texture(
    generator: TextureGenerator,
    shape: PreparedShape,
    photo: Photo,
    view: FramedView,
    photo_noc: torch.Tensor | None,
    vgg,
    cfg: TransferConfig,
    device: torch.device,
    show_progress: bool = True,
    generator_lit: bool = False,
    known_light: LightStart | None = None,
) -> TransferResult:
    """Optimise the texture of ``shape`` to look like ``photo`` (Equation 2, then refinement).

    Stage 2 modifies ``generator`` in place (its last ``refine_blocks`` synthesis blocks): pass a copy to keep it.
    photo: image (1,3,R,R), mask (1,1,R,R); view: noc (R,R,3), mask (1,1,R,R); ``photo_noc`` (R,R,3), needed with
    ``cfg.use_noc`` and ``cfg.use_patches``. ``generator_lit`` (trained under the light prior) is what ``cfg.light``
    'auto' follows; ``known_light``, the photo's light when known, is held there (the benchmarks' oracle).
    ``cfg.w_colour`` adds the low-pass colour loss, ``cfg.w_mirror`` the photo across the mirror (:class:`MirrorTerm`).
    """
    check_query(photo, view, photo_noc, "transfer_texture")
    loss_of = PhotoLoss(photo, view, photo_noc, vgg, cfg, device)
    batch = collate_shapes([shape]).to(device)
    generator = generator.to(device).requires_grad_(False)
    samples = rasterize_batch(batch, view.mvp.to(device), (view.render_size, view.render_size))
    light = photo_light(photo, view, batch, samples, cfg, generator_lit, known_light)
    renders = _FieldRenders(generator, batch, view, samples, light, cfg.resolution, device)
    mirror = MirrorTerm.of(shape, photo, view, photo_noc, batch, samples, vgg, cfg, device)
    ws = starting_latent(generator, renders.at_photo, loss_of, cfg, device).requires_grad_(True)

    def styles() -> torch.Tensor:
        return ws.expand(1, generator.num_ws, -1)

    result = TransferResult(ws=ws, render=torch.empty(0), mirror="xyz"[mirror.axis] if mirror is not None else None)
    light_params = list(light.parameters()) if light is not None and not (cfg.light_fixed or known_light) else []

    def optimise(stage: str, params: list[torch.Tensor], iters: int, use_global: bool, lr: float, anchors=()) -> None:
        loss = _stage_loss(loss_of, renders, styles, use_global, anchors, cfg.w_anchor, mirror, cfg.w_mirror)
        run_stage(stage, params, iters, lr, loss, result, show_progress)

    # The light is optimised in both stages: stage 2 changes the colours it has to explain.
    optimise("latent", [ws] + light_params, cfg.latent_iters, use_global=True, lr=cfg.lr)
    if cfg.refine and cfg.refine_iters > 0:
        ws.requires_grad_(False)
        params = generator.last_synthesis_parameters(cfg.refine_blocks)
        for p in params:
            p.requires_grad_(True)
        anchors = (
            unseen_anchors(
                shape,
                view,
                batch,
                [samples] + ([mirror.samples] if mirror is not None else []),
                cfg,
                device,
                renders.unlit,
                styles,
            )
            if cfg.w_anchor > 0
            else []
        )
        # Stage 2 uses the patch loss without the global one (paper), plus the colour loss when it is on;
        # without patches it keeps the global loss.
        optimise(
            "refine",
            params + light_params,
            cfg.refine_iters,
            use_global=not cfg.use_patches,
            lr=cfg.refine_lr or cfg.lr,
            anchors=anchors,
        )
        for p in params:
            p.requires_grad_(False)
    with torch.no_grad():
        result.render = renders.at_photo(styles()).cpu()
    result.ws = styles().detach().clone()
    result.light, result.light_start = (light.describe(), asdict(light.start)) if light is not None else (None, None)
    return result


class _FieldRenders:
    """The generator's field on one prepared shape (a batch of one), rendered on grey and cropped as the
    transfer's views are; its encoder's features computed once."""

    def __init__(
        self,
        generator: TextureGenerator,
        batch,
        view: FramedView,
        samples,
        light: PhotoLight | None,
        resolution: int,
        device: torch.device,
    ):
        self.generator, self.batch, self.view, self.samples, self.light = generator, batch, view, samples, light
        self.resolution = resolution
        self.device = device
        self.encoded = [e.detach() for e in generator.encoder(batch)]
        self.grey = torch.zeros(1, 3, device=self.device)

    def at_photo(self, ws: torch.Tensor) -> torch.Tensor:
        """(1, 3, R, R) the texture of styles ``ws`` at the photo's view, lit by the photo's light when there is one."""
        return self._render(ws, self.view, self.samples, self.light.lights() if self.light is not None else None)

    def at_mirror(self, ws: torch.Tensor, mirror: MirrorTerm) -> torch.Tensor:
        """(1, 3, R, R) the same at the mirrored pose, lit by the photo's light mirrored with the camera."""
        lights = self.light.lights(mirror.view.azimuth) if self.light is not None else None
        return self._render(ws, mirror.view, mirror.samples, lights)

    def unlit(self, ws: torch.Tensor, at: FramedView, at_samples) -> torch.Tensor:
        """(1, 3, R, R) albedo of the texture at another view, cropped as that view's object."""
        return self._render(ws, at, at_samples, None)

    def _render(self, ws: torch.Tensor, view: FramedView, samples, lights) -> torch.Tensor:
        size = (view.render_size,) * 2
        full = render_field_views(
            self.generator,
            self.batch,
            ws,
            view.mvp.to(self.device),
            size,
            self.grey,
            encoded=self.encoded,
            noise_mode="none",
            samples=samples,
            lights=lights,
        ).images
        return crop_square(full, view.box, self.resolution)


@dataclass
class MirrorTerm:
    """The photo read across the mesh's mirror plane: what a camera mirrored across it sees of a
    mirror-symmetric object is the photo flipped left to right (:func:`mesh2tex.transfer.photo.mirror_query`).
    The render at that mirrored pose is held to the flipped photo by the same losses as the photo's, on the
    pixels whose surface the photo's own view does not show: the side of a chair or a car that the photo
    shows paints the other, which nothing else holds (the unseen sides, docs/results/transfer.md), and
    the surfaces both views show are held by the photo alone (a photo from the front or the back,
    mirrored, shows the same surfaces again and would only weigh them twice). ``axis``: 0 (x) or 2 (z),
    the plane's normal; ``view``: the mirrored view, its mask those new pixels; ``samples``: the mesh
    rasterized at the mirrored view (its full render)."""

    axis: int
    view: FramedView
    samples: object
    loss: PhotoLoss

    @classmethod
    def of(
        cls,
        shape: PreparedShape,
        photo: Photo,
        view: FramedView,
        photo_noc,
        batch,
        photo_samples,
        vgg,
        cfg: TransferConfig,
        device,
    ) -> MirrorTerm | None:
        """The term for this query (``photo_samples``: the mesh rasterized at the photo's view), or None when
        ``cfg.w_mirror`` is 0, the mesh has no mirror plane (:func:`mesh2tex.geometry.symmetry.mirror_axis`)
        or the mirrored view shows fewer than 16 pixels of surface the photo does not (in its render, and
        in the flipped photo's mask)."""
        axis = mirror_axis(shape.vertices[0], shape.triangles(0)) if cfg.w_mirror > 0 else None
        if axis is None:
            return None
        flipped, mirrored, noc = mirror_query(shape, photo, view, photo_noc, axis, cfg)
        samples = rasterize_batch(batch, mirrored.mvp.to(device), (mirrored.render_size, mirrored.render_size))
        new = unseen_pixels(seen_triangles(batch, [photo_samples], device), mirrored, samples, cfg).to(mirrored.mask)
        flipped = Photo(image=flipped.image, mask=flipped.mask * new)
        mirrored = dataclasses.replace(mirrored, mask=mirrored.mask * new)
        # both sides of every loss need pixels: an estimated mask that misses the new surfaces leaves none
        if min(float(flipped.mask.sum()), float(mirrored.mask.sum())) < 16:
            return None
        # its own patch pairs: the mirrored view's are drawn apart from the photo's
        loss = PhotoLoss(flipped, mirrored, noc, vgg, dataclasses.replace(cfg, seed=cfg.seed + 1), device)
        return cls(axis, mirrored, samples, loss)


def _stage_loss(
    loss_of: PhotoLoss,
    renders: _FieldRenders,
    styles,
    use_global: bool,
    anchors,
    w_anchor: float,
    mirror: MirrorTerm | None = None,
    w_mirror: float = 0.0,
):
    """loss(step): the photo loss of the render at the photo's view; with ``mirror``, plus ``w_mirror`` times
    its loss at the mirrored view; with ``anchors`` [(view, samples, mask, target colours)], plus
    ``w_anchor`` times the low-pass colour loss at anchor ``step % len(anchors)``."""

    def loss(i: int) -> torch.Tensor:
        total, _ = loss_of(renders.at_photo(styles()), use_global)
        if mirror is not None:
            total = total + w_mirror * mirror.loss(renders.at_mirror(styles(), mirror), use_global)[0]
        if anchors:
            at, at_samples, mask, target = anchors[i % len(anchors)]
            unlit = renders.unlit(styles(), at, at_samples)
            total = total + w_anchor * lowpass_colour_loss(unlit, mask, target, mask, loss_of.colour_sigma)
        return total

    return loss


@torch.no_grad()
def starting_latent(generator: TextureGenerator, render, loss_of, cfg: TransferConfig, device) -> torch.Tensor:
    """Stage 1's starting latent: the mean latent ``w_avg``, or with ``cfg.latent_starts`` > 1 the best
    scoring of it and random latents (truncation 0.7). (1, num_ws, w_dim) for w_plus; (1, 1, w_dim),
    shared by every style input, for w."""
    num_ws = generator.num_ws
    starts = [mean_latent(generator)]
    if cfg.latent_starts > 1:
        z = torch.randn(
            cfg.latent_starts - 1, generator.cfg.z_dim, generator=torch.Generator().manual_seed(cfg.seed)
        ).to(device)
        starts += list(generator.mapping(z, truncation_psi=0.7).split(1))  # each (1, num_ws, w_dim)
        # Score each start as stage 1 will see it; the patch pairs are drawn from their own generator
        # so that the run's later pairs do not depend on how many starts were tried.
        scores = [
            float(
                loss_of(render(w.expand(1, num_ws, -1)), use_global=True, pick=torch.Generator().manual_seed(cfg.seed))[
                    0
                ]
            )
            for w in starts
        ]
        starts = [starts[min(range(len(scores)), key=scores.__getitem__)]]
    return (starts[0][:, :1] if cfg.latent_space == "w" else starts[0].expand(1, num_ws, -1)).clone()


def run_stage(
    stage: str, params: list[torch.Tensor], iters: int, lr: float, loss, result: TransferResult, show_progress: bool
) -> None:
    """Adam on ``params`` for ``iters`` steps of ``loss(step)``; the loss curve and seconds go into ``result``
    under ``stage``. InputError when the loss becomes non-finite."""
    opt = torch.optim.Adam(params, lr=lr)
    history: list[float] = []
    start = time.perf_counter()
    iterator = progress_bar(range(iters), desc=f"transfer {stage}") if show_progress else range(iters)
    for i in iterator:
        total = loss(i)
        if not torch.isfinite(total):
            raise InputError(f"transfer {stage}: the style loss became {float(total)}; lower the learning rate (lr)")
        opt.zero_grad(set_to_none=True)
        total.backward()
        opt.step()
        value = float(total.detach())
        history.append(round(value, 6))
        if show_progress:
            iterator.set_postfix(loss=f"{value:.4f}")
    result.losses[stage] = history
    result.seconds[stage] = round(time.perf_counter() - start, 2)


@torch.no_grad()
def unseen_anchors(
    shape: PreparedShape,
    view: FramedView,
    batch,
    seen_samples: list,
    cfg: TransferConfig,
    device: torch.device,
    render_unlit,
    styles,
) -> list:
    """The surfaces the photo does not show, as stage 1 painted them: for each of ``cfg.anchor_views``
    views around the object (the photo's elevation, azimuths from 30 degrees after the photo's), a tuple
    (view, its surface samples, mask (1,1,R,R) of the pixels whose triangle none of ``seen_samples`` (the
    photo's view's, and the mirrored view's when the photo is read across a mirror) covers, albedo
    (1,3,R,R) of the current texture there). Views that show no such pixel are left out.

    Stage 2 fits the last synthesis blocks to the photo's side alone and nothing holds the other sides;
    the low-pass colour loss against these renders (``cfg.w_anchor``) keeps them on the generator's
    prior that stage 1 chose, while the photo's side is refined.
    """
    check_view(view, "unseen_anchors")
    if view.distance <= 0:
        raise ValueError("unseen_anchors: the view records no camera distance (build it with view_at_pose)")
    seen = seen_triangles(batch, seen_samples, device)
    anchors = []
    for k in range(cfg.anchor_views):
        azimuth = view.azimuth + 30.0 + 360.0 * k / cfg.anchor_views
        at = view_at_pose(shape, azimuth, view.elevation, view.distance, view.fov, cfg)
        at_samples = rasterize_batch(batch, at.mvp.to(device), (at.render_size, at.render_size))
        mask = unseen_pixels(seen, at, at_samples, cfg)
        if mask.sum() >= 16:
            anchors.append((at, at_samples, mask, render_unlit(styles(), at, at_samples)))
    return anchors


def seen_triangles(batch, seen_samples: list, device: torch.device) -> torch.Tensor:
    """[T] bool over the batch's triangles: those that cover a pixel of any of ``seen_samples`` (rasterizations)."""
    seen = torch.zeros(batch.triangles().shape[0], dtype=torch.bool, device=device)
    for samples in seen_samples:
        seen[samples.triangle_id[samples.triangle_id >= 0]] = True
    return seen


def unseen_pixels(seen: torch.Tensor, at: FramedView, at_samples, cfg: TransferConfig) -> torch.Tensor:
    """(1, 1, R, R) float {0, 1}: the pixels of view ``at`` (its crop; ``at_samples`` its full rasterization)
    whose triangle is not ``seen`` ([T] bool)."""
    ids = at_samples.triangle_id
    unseen = ((ids >= 0) & ~seen[ids.clamp_min(0)]).float().unsqueeze(1)  # (1,1,S,S)
    return (crop_square(unseen, at.box, cfg.resolution) > 0.5).float()
