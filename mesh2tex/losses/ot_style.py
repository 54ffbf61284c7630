"""The relaxed optimal-transport style loss of texture NCAs (Kolkin et al. 2019, as MeshNCA uses it).

An image becomes one feature *set* per layer: its RGB pixels (layer 0) and the VGG19 style
activations (:mod:`mesh2tex.nn.vgg`), each position a point in R^C. Two sets A (render) and B
(exemplar) are compared by

    W(A, B)  = mean_i min_j D(A_i, B_j),   D = cosine distance (+ L2 distance on the RGB layer)
    L_W      = max(W(A, B), W(B, A))                       relaxed earth mover's distance
    L_M      = |m_A - m_B|_1 / C + |T_A - T_B|_1 / C^2     means m and covariances T
    loss     = mean over images of sum over layers of (L_W + L_M)

Departure from the reference: only positions on the object enter a render's sets (the mask,
area-resampled to each layer, above 0.5), where the reference feeds whole renders, background
included. Our renders show a mesh over a constant background: counting the background would ask the
automaton to paint the exemplar's statistics *and* make room for a grey that the exemplar lacks.

Sets are subsampled to at most ``max_points`` random positions (the cost matrices are
|A| x |B|); the exemplar's features are computed once (:class:`ExemplarFeatures`).

Conventions: images (N, 3, H, W) in [-1, 1]; masks (N, 1, H, W) in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape, check_type
from mesh2tex.losses.structure import (
    NETWORK_FREE_LOSSES,
    STRUCTURE_LOSSES,
    check_point_sets,
    exemplar_band_statistics,
    exemplar_patch_sets,
    patch_loss,
    ps_loss,
    sw_distance,
)
from mesh2tex.losses.style import masked_gram

# "ot" and "gram" here; "sw" (sliced Wasserstein on the same features), "ps" (oriented-band
# statistics) and "patch" (raw multi-scale patches; these two need no network) in :mod:`mesh2tex.losses.structure`.
STYLE_LOSSES = ("ot", "gram") + STRUCTURE_LOSSES


def needs_vgg(kind: str) -> bool:
    """Whether the style loss ``kind`` (one of :data:`STYLE_LOSSES`) reads VGG features."""
    return kind not in NETWORK_FREE_LOSSES


def image_layers(vgg, images: torch.Tensor, depth: int) -> list[torch.Tensor]:
    """[images (N, 3, H, W), the first ``depth`` VGG style activations]: (N, C_l, H_l, W_l) each."""
    check_shape(images, "image_layers: images", ("N", 3, "H", "W"), dtype="float")
    return [images] + (list(vgg(images, depth=depth)) if depth > 0 else [])


def _positions(
    mask: torch.Tensor | None, size: tuple[int, int], max_points: int, generator: torch.Generator | None, device
) -> torch.Tensor:
    """Flat indices (P,) of at most ``max_points`` random positions of an (h, w) map inside ``mask`` (1, H, W)."""
    h, w = size
    if mask is None:
        index = torch.arange(h * w, device=device)
    else:
        small = F.adaptive_avg_pool2d(mask[None].float(), (h, w)).reshape(-1)
        index = (small > 0.5).nonzero().squeeze(1)
    if index.numel() > max_points:
        pick = torch.randperm(index.numel(), generator=generator)[:max_points].to(index.device)
        index = index[pick]
    return index


def feature_sets(
    layers: list[torch.Tensor], mask: torch.Tensor | None, max_points: int, generator: torch.Generator | None = None
) -> list[torch.Tensor]:
    """Per layer, the (P_l, C_l) features of image 0 of ``layers`` ((N, C_l, H_l, W_l) each) at the positions
    inside ``mask`` (1, H, W), area-resampled to each layer (all positions with mask None)."""
    check_shape(mask, "feature_sets: mask", (1, None, None), optional=True)
    for index, feats in enumerate(check_type(layers, "feature_sets: layers", list)):
        check_shape(feats, f"feature_sets: layers[{index}]", (None, None, None, None), dtype="float")
    sets = []
    for feats in layers:
        c, h, w = feats.shape[1:]
        index = _positions(mask, (h, w), max_points, generator, feats.device)
        sets.append(feats[0].reshape(c, h * w)[:, index].t())
    return sets


def _check_sets(a: torch.Tensor, b: torch.Tensor, function: str) -> None:
    """a (P, C) and b (Q, C) float, named ``function: a`` and ``function: b``."""
    sizes = check_shape(a, f"{function}: a", ("P", "C"), dtype="float")
    check_shape(b, f"{function}: b", ("Q", "C"), sizes=sizes, dtype="float")


def relaxed_emd(a: torch.Tensor, b: torch.Tensor, l2: bool) -> torch.Tensor:
    """L_W between point sets a (P, C) and b (Q, C)."""
    _check_sets(a, b, "relaxed_emd")
    cost = 1.0 - F.normalize(a, dim=1) @ F.normalize(b, dim=1).t()
    if l2:
        cost = cost + torch.cdist(a, b)
    return torch.maximum(cost.min(dim=1).values.mean(), cost.min(dim=0).values.mean())


def moment_loss(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """L_M between point sets a (P, C) and b (Q, C): mean absolute differences of means and covariances."""
    _check_sets(a, b, "moment_loss")
    ma, mb = a.mean(0), b.mean(0)
    ca = (a - ma).t() @ (a - ma) / max(a.shape[0] - 1, 1)
    cb = (b - mb).t() @ (b - mb) / max(b.shape[0] - 1, 1)
    return (ma - mb).abs().mean() + (ca - cb).abs().mean()


def ot_style_distance(render_sets: list[torch.Tensor], exemplar_sets: list[torch.Tensor]) -> torch.Tensor:
    """sum over layers of L_W + L_M (layer 0, RGB, with the L2 term); an empty render set counts 0.
    render_sets (P_l, C_l) and exemplar_sets (Q_l, C_l), one of each per layer."""
    check_point_sets(render_sets, exemplar_sets, "ot_style_distance")
    total = render_sets[0].new_zeros(())
    for layer, (a, b) in enumerate(zip(render_sets, exemplar_sets)):
        if a.shape[0] < 2:
            continue
        total = total + relaxed_emd(a, b, l2=layer == 0) + moment_loss(a, b)
    return total


@dataclass
class ExemplarFeatures:
    """An exemplar image's layers, computed once. image (1, 3, H, W) in [-1, 1]; layers as :func:`image_layers`."""

    image: torch.Tensor
    layers: list[torch.Tensor]
    # the "ps" statistics and the "patch" sets, made on first use
    band_stats: dict[str, torch.Tensor] = field(default_factory=dict, repr=False)
    patches: list[torch.Tensor] = field(default_factory=list, repr=False)

    def band_statistics(self) -> dict[str, torch.Tensor]:
        if not self.band_stats:
            self.band_stats.update(exemplar_band_statistics(self.image))
        return self.band_stats

    def patch_sets(self) -> list[torch.Tensor]:
        if not self.patches:
            self.patches.extend(exemplar_patch_sets(self.image))
        return self.patches

    @classmethod
    def compute(cls, vgg, image: torch.Tensor, depth: int) -> "ExemplarFeatures":
        """The layers of ``image`` (1, 3, H, W) in [-1, 1] to ``depth`` VGG layers (``vgg`` unused with depth 0)."""
        check_shape(image, "ExemplarFeatures.compute: image", (1, 3, None, None), dtype="float")
        with torch.no_grad():
            return cls(image=image, layers=[t.detach() for t in image_layers(vgg, image, depth)])


def style_loss(
    vgg,
    images: torch.Tensor,
    masks: torch.Tensor,
    exemplar: ExemplarFeatures,
    kind: str = "ot",
    max_points: int = 1024,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Mean over the N images of their style distance to the exemplar (see the module docstring).

    images (N, 3, H, W) in [-1, 1], masks (N, 1, H, W); ``kind`` "ot" (relaxed optimal transport and
    moments), "gram" (squared differences of masked Gram matrices, the project's transfer loss,
    summed over the layers), "sw" (sliced Wasserstein on the same layers), "ps" (oriented-band
    statistics of the pixels) or "patch" (sliced Wasserstein on raw multi-scale patches, at most
    ``max_points`` per octave and image); ``vgg`` unused by the last two. Differentiable with respect to ``images``.
    """
    sizes = check_shape(images, "style_loss: images", ("N", 3, "H", "W"), dtype="float")
    check_shape(masks, "style_loss: masks", ("N", 1, "H", "W"), sizes=sizes)
    check_type(exemplar, "style_loss: exemplar", ExemplarFeatures)
    if kind not in STYLE_LOSSES:
        raise ValueError(f"style loss must be one of {STYLE_LOSSES}, got {kind!r}")
    if kind == "ps":
        return ps_loss(images, masks, exemplar.band_statistics())
    if kind == "patch":
        return patch_loss(images, masks, exemplar.patch_sets(), max_points, generator)
    depth = len(exemplar.layers) - 1
    layers = image_layers(vgg, images, depth)
    losses = []
    for n in range(images.shape[0]):
        if kind == "gram":
            mine = [masked_gram(f[n : n + 1], masks[n : n + 1]) for f in layers]
            theirs = [masked_gram(f) for f in exemplar.layers]
            losses.append(sum((x - y).square().mean() for x, y in zip(mine, theirs)))
            continue
        render_sets = feature_sets([f[n : n + 1] for f in layers], masks[n], max_points, generator)
        exemplar_sets = feature_sets(exemplar.layers, None, max_points, generator)
        if kind == "sw":
            losses.append(sw_distance(render_sets, exemplar_sets, generator))
        else:
            losses.append(ot_style_distance(render_sets, exemplar_sets))
    return torch.stack(losses).mean()
