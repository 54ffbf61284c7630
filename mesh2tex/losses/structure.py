"""Weight-free texture losses that see structure: stripes' direction, checks' corners, a period.

Two kinds, both comparing only the object's pixels of a render with a whole exemplar image:

``sw`` - **sliced Wasserstein on random-filter features** (after Heitz et al., CVPR 2021). The
    same feature sets as the relaxed-OT loss (RGB and the random-weight VGG19 layers, object
    positions only, :func:`mesh2tex.losses.ot_style.feature_sets`) are projected on as many random
    unit directions as the layer has channels, fresh every call; both sides' projections are
    sorted and the render's are matched to the exemplar's at the same quantiles:

        SW_l(A, B) = mean over directions d and ranks i of (sort(A d)_i - Q_B,d(i))^2 / s_l
        loss       = sum over layers l of SW_l

    where Q_B,d is the exemplar's sorted projections read at the render's quantiles (the two sets
    may differ in size) and s_l the exemplar layer's mean squared feature (so every layer counts
    alike whatever its activation scale). Matching whole 1D distributions, not nearest neighbours
    and two moments, asks for the right *proportions* of every feature, which is what a
    random-weight network's features need to pin down a structure.

``ps`` - **oriented-band statistics** in the spirit of Portilla and Simoncelli (2000), written here
    on a small spatial filter bank so that a mask can be honoured exactly. The image's luminance
    is split into ``scales`` octaves (5-tap binomial blur and decimation); at each octave, complex
    oriented filters (a Gaussian-windowed complex exponential, ``orientations`` directions over
    180 degrees, zero mean) give band responses b = r + i q. Statistics over the object positions
    where the whole filter lies on the object:

        colour      mean (3), covariance (3 x 3) and 16 quantiles per channel of the RGB pixels
        marginals   skewness and kurtosis of each octave's low-pass luminance
        energy      mean |b| per octave and orientation (which directions carry structure)
        autocorr    the real band's auto-correlation and the magnitude's auto-covariance (over its
                    squared mean) over a (2L+1)^2 lag window (period and regularity)
        cross-ori   covariance of magnitudes between orientations at one octave, over the product
                    of their means (checks: two directions present together; stripes: one)
        cross-scale the same relative covariance of each magnitude with the next coarser
                    octave's, and the correlation of the real band with the coarser band's
                    phase-doubled response (edges and corners: features aligned across scales)
        low-pass    each octave's low-pass luminance's auto-correlation over a 5 x 5 window

    The loss is the sum over the groups of the squared difference relative to the exemplar's
    group, w_g |a_g - b_g|^2 / (|b_g|^2 + eps), so that no group wins by its units; the colour and
    energy groups weigh 10 (w_g, :data:`GROUP_WEIGHTS`), or a flat colour would score better than
    any wrong structure and an automaton would settle on it.

``patch`` - **multi-scale raw-patch sliced Wasserstein**: the distribution of the image's own
    ``size`` x ``size`` RGB patches at ``levels`` octaves (2 x 2 area averages between them), no
    filters and no network, matched to the exemplar's patches of the same octave by sliced
    Wasserstein (as ``sw``, fresh random directions every call, as many as the patch has values):

        loss = sum over octaves l of mean over directions d and ranks i of (sort(P_l d)_i - Q_l,d(i))^2

    A patch holds colour, contrast, edge direction and, at the coarser octaves, the period and the
    corners together: matching the whole distribution of patches (the seeds' patch-based
    multi-scale OT, sliced) asks for checks with corners where oriented-band statistics are content
    with blobs of the right energy. Only render patches wholly on the object count (a coarse pixel
    is on the object when its four finer ones are). The exemplar's patches are taken as they are,
    not turned: the pattern's direction on the surface is the direction field's job.

Conventions: images (N, 3, H, W) in [-1, 1]; masks (N, 1, H, W) in [0, 1] (object above 0.5).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape, check_type

STRUCTURE_LOSSES = ("sw", "ps", "patch")
NETWORK_FREE_LOSSES = ("ps", "patch")  # the structure losses that need no VGG network
PATCH_SIZE = 5  # side of the ``patch`` loss's raw patches
PATCH_LEVELS = 4  # octaves of the ``patch`` loss

_BINOMIAL = torch.tensor([1.0, 4.0, 6.0, 4.0, 1.0]) / 16.0
_INSIDE = 1.0 - 1e-4  # an eroded mask's average above this: every pixel of the support on the object
QUANTILES = 16  # colour quantiles per channel in the "ps" statistics
# Relative weights of statistic groups (by name prefix; others 1). Correlation-type groups of a flat
# render are all 0, an error of 1 each, while a structured but wrong render can score 2 to 4 per
# group: unweighted, a flat colour beats noise of the exemplar's own colours and the automaton
# settles on it. Weighting the colour and band-energy groups makes contrast and palette come first.
GROUP_WEIGHTS = {"colour": 10.0, "energy": 10.0}
_MIN_POSITIONS = 8  # octaves with fewer valid positions than this are left out of a render's statistics


# ------------------------------------------------------------------------------ sliced Wasserstein
def quantile_resample(sorted_values: torch.Tensor, count: int) -> torch.Tensor:
    """(Q, K) values sorted along dim 0 -> (count, K): linear interpolation at the quantiles (i + 0.5) / count."""
    check_shape(sorted_values, "quantile_resample: sorted_values", ("Q", "K"), dtype="float")
    q = sorted_values.shape[0]
    if q == count:
        return sorted_values
    position = (
        (torch.arange(count, dtype=sorted_values.dtype, device=sorted_values.device) + 0.5) * (q / count) - 0.5
    ).clamp(0, q - 1)
    low = position.floor().long()
    high = (low + 1).clamp(max=q - 1)
    t = (position - low.to(position.dtype))[:, None]
    return sorted_values[low] * (1 - t) + sorted_values[high] * t


def sliced_wasserstein2(a: torch.Tensor, b: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
    """Squared sliced Wasserstein-2 distance between point sets a (P, C) and b (Q, C) along
    ``directions`` (C, K) unit columns: the mean over directions and ranks of the squared difference
    of sorted projections, b read at a's quantiles. Differentiable with respect to a and b."""
    sizes = check_shape(a, "sliced_wasserstein2: a", ("P", "C"), dtype="float")
    check_shape(b, "sliced_wasserstein2: b", ("Q", "C"), sizes=sizes, dtype="float")
    check_shape(directions, "sliced_wasserstein2: directions", ("C", "K"), sizes=sizes, dtype="float")
    pa = torch.sort(a @ directions, dim=0).values
    pb = quantile_resample(torch.sort(b @ directions, dim=0).values, a.shape[0])
    return (pa - pb).square().mean()


def random_directions(channels: int, count: int, generator: torch.Generator | None, device, dtype) -> torch.Tensor:
    """(channels, count) random unit vectors (columns)."""
    d = torch.randn(channels, count, generator=generator).to(device=device, dtype=dtype)
    return d / d.norm(dim=0, keepdim=True).clamp_min(1e-12)


def check_point_sets(render_sets: list[torch.Tensor], exemplar_sets: list[torch.Tensor], function: str) -> None:
    """Raise unless both are lists of one length (>= 1) of point sets, per layer l (P_l, C_l) and (Q_l, C_l) float;
    the message names ``function`` and the set."""
    check_type(render_sets, f"{function}: render_sets", list)
    check_type(exemplar_sets, f"{function}: exemplar_sets", list)
    if len(render_sets) != len(exemplar_sets) or not render_sets:
        raise ValueError(
            f"{function}: render_sets and exemplar_sets must hold one set per layer alike, "
            f"got {len(render_sets)} and {len(exemplar_sets)}"
        )
    for layer, (a, b) in enumerate(zip(render_sets, exemplar_sets)):
        sizes = check_shape(a, f"{function}: render_sets[{layer}]", ("P", "C"), dtype="float")
        check_shape(b, f"{function}: exemplar_sets[{layer}]", ("Q", "C"), sizes=sizes, dtype="float")


def sw_distance(
    render_sets: list[torch.Tensor],
    exemplar_sets: list[torch.Tensor],
    generator: torch.Generator | None = None,
    min_projections: int = 32,
) -> torch.Tensor:
    """sum over layers of SW_l (module docstring); sets (P_l, C_l) and (Q_l, C_l); render sets under 2 points count
    0."""
    check_point_sets(render_sets, exemplar_sets, "sw_distance")
    total = render_sets[0].new_zeros(())
    for a, b in zip(render_sets, exemplar_sets):
        if a.shape[0] < 2:
            continue
        scale = b.square().sum(1).mean().clamp_min(1e-8) / b.shape[1]  # mean squared feature per channel
        directions = random_directions(a.shape[1], max(a.shape[1], min_projections), generator, a.device, a.dtype)
        total = total + sliced_wasserstein2(a, b, directions) / scale
    return total


# ----------------------------------------------------------------------- oriented band statistics
def _blur_down(images: torch.Tensor) -> torch.Tensor:
    """(N, C, H, W) -> (N, C, ceil(H/2), ceil(W/2)): binomial blur (reflect padding) and decimation."""
    kernel = (_BINOMIAL[:, None] * _BINOMIAL[None, :]).to(images)
    c = images.shape[1]
    return F.conv2d(F.pad(images, (2, 2, 2, 2), mode="reflect"), kernel.expand(c, 1, 5, 5), groups=c)[..., ::2, ::2]


def oriented_filters(orientations: int = 4, size: int = 7, frequency: float = 0.25, sigma: float = 1.4) -> torch.Tensor:
    """(2 * orientations, 1, size, size) float32: per orientation theta_k = k pi / K, the real (even)
    and imaginary (odd) parts of exp(2 pi i f (x cos + y sin)) under a Gaussian of ``sigma`` px, each
    made zero-mean (no response to flat colour) and scaled to unit L2 norm."""
    r = torch.arange(size, dtype=torch.float64) - (size - 1) / 2
    y, x = torch.meshgrid(r, r, indexing="ij")
    window = torch.exp(-(x**2 + y**2) / (2 * sigma**2))
    bank = []
    for k in range(orientations):
        theta = math.pi * k / orientations
        phase = 2 * math.pi * frequency * (x * math.cos(theta) + y * math.sin(theta))
        for part in (torch.cos(phase), torch.sin(phase)):
            f = part * window
            f = f - f.mean()
            bank.append(f / f.norm())
    return torch.stack(bank)[:, None].float()


def _masked_moments(x: torch.Tensor, w: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """x (C, P), weights w (P,) summing to 1 -> mean (C,), centred x (C, P)."""
    mean = x @ w
    return mean, x - mean[:, None]


def _autocorrelation(maps: torch.Tensor, valid: torch.Tensor, lag: int, relative: bool = False) -> torch.Tensor:
    """maps (C, h, w), valid (h, w) bool -> (C, L) covariances of each centred map with itself shifted by
    the lags (dy, dx) of the half window 0 <= dy <= lag, |dx| <= lag (without (0, 0) and its mirror
    duplicates), over the pairs where both ends are valid, divided by the variance (a correlation), or
    with ``relative`` by the squared mean: for magnitudes, which can be nearly constant (a pure
    sinusoid), where a correlation would be a ratio of two tiny numbers."""
    c, h, w = maps.shape
    v = valid.to(maps.dtype)
    n = v.sum().clamp_min(1)
    mean = (maps * v).sum((1, 2)) / n
    centred = (maps - mean[:, None, None]) * v
    var = (mean.square() if relative else centred.square().sum((1, 2)) / n) + 1e-8
    out = []
    for dy in range(0, lag + 1):
        for dx in range(-lag, lag + 1):
            if dy == 0 and dx <= 0:
                continue
            if dy >= h or abs(dx) >= w:
                out.append(torch.zeros_like(var))
                continue
            a = centred[:, dy:, max(dx, 0) : w + min(dx, 0)]
            b = centred[:, : h - dy, max(-dx, 0) : w - max(dx, 0)]
            both = v[dy:, max(dx, 0) : w + min(dx, 0)] * v[: h - dy, max(-dx, 0) : w - max(dx, 0)]
            out.append((a * b).sum((1, 2)) / both.sum().clamp_min(1) / var)
    return torch.stack(out, 1)


def _correlation(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """x (A, P), y (B, P) -> (A, B) correlation coefficients of the centred rows."""
    x, y = x - x.mean(1, keepdim=True), y - y.mean(1, keepdim=True)
    cov = x @ y.t() / x.shape[1]
    return cov / (x.square().mean(1)[:, None] * y.square().mean(1)[None, :]).clamp_min(1e-12).sqrt()


def _relative_covariance(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """x (A, P), y (B, P) positive (magnitudes) -> (A, B) covariances over the products of the means:
    0 for constant rows, where a correlation would be undefined."""
    mx, my = x.mean(1, keepdim=True), y.mean(1, keepdim=True)
    return (x - mx) @ (y - my).t() / x.shape[1] / (mx * my.t() + 1e-8)


def band_statistics(
    image: torch.Tensor, mask: torch.Tensor | None = None, scales: int = 4, orientations: int = 4, lag: int = 3
) -> dict[str, torch.Tensor]:
    """The statistics of the ``ps`` loss (module docstring) of one image.

    image (1, 3, H, W) in [-1, 1]; mask (1, 1, H, W) in [0, 1] or None (every pixel). Returns a dict
    of named 1D tensors; octaves with too few valid positions are left out (their keys absent), so
    compare two dicts on their shared keys. Differentiable with respect to ``image``.
    """
    sizes = check_shape(image, "band_statistics: image", (1, 3, "H", "W"), dtype="float")
    check_shape(mask, "band_statistics: mask", (1, 1, "H", "W"), sizes=sizes, optional=True)
    rgb = (image[0] + 1) / 2  # (3, H, W) in [0, 1]
    full = torch.ones_like(rgb[:1]) if mask is None else (mask[0] > 0.5).to(rgb.dtype)
    pixels = rgb[:, full[0] > 0.5]  # (3, P)
    if pixels.shape[1] < _MIN_POSITIONS:
        return {}
    stats = _colour_statistics(pixels)

    bank = oriented_filters(orientations).to(rgb)
    k = bank.shape[-1]
    luminance = (0.299 * rgb[0] + 0.587 * rgb[1] + 0.114 * rgb[2])[None, None]  # (1, 1, H, W)
    m = full[None]  # (1, 1, H, W)
    previous = None  # the finer octave's (magnitude, complex response, valid) for the cross-scale terms
    for s in range(scales):
        if min(luminance.shape[-2:]) < k:
            break
        # Filter support wholly on the object: erode the mask by the kernel.
        valid = F.avg_pool2d(m, k, stride=1, padding=k // 2, count_include_pad=True)[0, 0] > _INSIDE
        response = F.conv2d(F.pad(luminance, (k // 2,) * 4, mode="reflect"), bank)[0]  # (2K, h, w)
        real, imag = response[0::2], response[1::2]  # (K, h, w) each
        magnitude = (real.square() + imag.square() + 1e-8).sqrt()
        lum_valid = m[0, 0] > 0.5
        count = int(valid.sum())
        if count >= _MIN_POSITIONS:
            mag = magnitude[:, valid]  # (K, P)
            stats[f"energy_{s}"] = mag.mean(1)
            stats[f"cross_orientation_{s}"] = _relative_covariance(mag, mag)[
                torch.triu_indices(orientations, orientations).unbind()
            ]
            stats[f"autocorr_band_{s}"] = _autocorrelation(real, valid, lag).reshape(-1)
            stats[f"autocorr_magnitude_{s}"] = _autocorrelation(magnitude, valid, lag, relative=True).reshape(-1)
            stats[f"autocorr_lowpass_{s}"] = _autocorrelation(luminance[0], valid, min(lag, 2)).reshape(-1)
            lum = luminance[0, 0][lum_valid]
            centred_lum = lum - lum.mean()
            var = centred_lum.square().mean() + 1e-8
            stats[f"marginal_{s}"] = torch.stack(
                [centred_lum.pow(3).mean() / var**1.5, centred_lum.pow(4).mean() / var**2]
            )
            if previous is not None:
                stats.update(_cross_scale_statistics(previous, real, imag, magnitude, valid, s))
            previous = (magnitude, real, valid)
        else:
            previous = None
        luminance = _blur_down(luminance)
        # The next octave's object: coarse pixels whose 5-tap blur saw only object pixels.
        m = (F.avg_pool2d(m, 5, stride=1, padding=2, count_include_pad=True) > _INSIDE).to(rgb.dtype)[..., ::2, ::2]
    return stats


def _colour_statistics(pixels: torch.Tensor) -> dict[str, torch.Tensor]:
    """The colour groups of :func:`band_statistics` from the object's pixels (3, P) in [0, 1]."""
    count = pixels.shape[1]
    w = torch.full((count,), 1.0 / count, dtype=pixels.dtype, device=pixels.device)
    mean, centred = _masked_moments(pixels, w)
    # The colour marginals themselves (a two-colour exemplar has two modes that a mean and a
    # covariance cannot tell from a blend): QUANTILES evenly spaced quantiles of each channel.
    ranks = ((torch.arange(QUANTILES, device=pixels.device) + 0.5) / QUANTILES * (count - 1)).round().long()
    return {
        "colour_mean": mean,
        "colour_cov": (centred @ centred.t() / count).reshape(-1),
        "colour_quantiles": torch.sort(pixels, dim=1).values[:, ranks].reshape(-1),
    }


def _cross_scale_statistics(
    finer: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    real: torch.Tensor,
    imag: torch.Tensor,
    magnitude: torch.Tensor,
    valid: torch.Tensor,
    s: int,
) -> dict[str, torch.Tensor]:
    """The cross-scale groups of octave ``s`` against the finer octave ``finer`` = (magnitude (K, 2h, 2w), real
    part (K, 2h, 2w), valid (2h, 2w)); this octave's real, imag, magnitude (K, h, w) and valid (h, w)."""
    fine_mag, fine_real, fine_valid = finer
    size = fine_mag.shape[-2:]
    up = lambda t: F.interpolate(t[None], size=size, mode="bilinear", align_corners=False)[0]  # noqa: E731
    # Bilinear upsampling mixes a coarse pixel's neighbours: they must be valid too.
    coarse_valid = (
        F.avg_pool2d(valid[None, None].to(real.dtype), 3, stride=1, padding=1, count_include_pad=True) > _INSIDE
    )
    both = fine_valid & (F.interpolate(coarse_valid.to(real.dtype), size=size, mode="nearest")[0, 0] > 0.5)
    if int(both.sum()) < _MIN_POSITIONS:
        return {}
    stats = {f"cross_scale_magnitude_{s}": _relative_covariance(fine_mag[:, both], up(magnitude)[:, both]).reshape(-1)}
    # Phase doubling: the coarse band b^2 / |b| oscillates at the finer octave's frequency,
    # so it correlates with the fine band where edges line up across scales.
    doubled_real = up((real.square() - imag.square()) / magnitude)[:, both]
    doubled_imag = up(2 * real * imag / magnitude)[:, both]
    coarse = torch.cat([doubled_real, doubled_imag])
    stats[f"cross_scale_phase_{s}"] = _correlation(fine_real[:, both], coarse).reshape(-1)
    return stats


def statistics_distance(
    mine: dict[str, torch.Tensor], theirs: dict[str, torch.Tensor], eps: float = 1e-2
) -> torch.Tensor:
    """sum over the shared groups of w_g |a_g - b_g|^2 / (|b_g|^2 + eps * size_g), w_g from :data:`GROUP_WEIGHTS`."""
    total = next(iter(theirs.values())).new_zeros(())
    for key, b in theirs.items():
        if key in mine:
            weight = next((w for prefix, w in GROUP_WEIGHTS.items() if key.startswith(prefix)), 1.0)
            total = total + weight * (mine[key] - b).square().sum() / (b.square().sum() + eps * b.numel())
    return total


def exemplar_band_statistics(image: torch.Tensor, **kwargs) -> dict[str, torch.Tensor]:
    """:func:`band_statistics` of a whole exemplar (1, 3, H, W), detached."""
    check_shape(image, "exemplar_band_statistics: image", (1, 3, None, None), dtype="float")
    with torch.no_grad():
        return {k: v.detach() for k, v in band_statistics(image, None, **kwargs).items()}


def ps_loss(images: torch.Tensor, masks: torch.Tensor, exemplar_stats: dict[str, torch.Tensor]) -> torch.Tensor:
    """Mean over the N images (N, 3, H, W) with masks (N, 1, H, W) of :func:`statistics_distance` to
    ``exemplar_stats`` (:func:`exemplar_band_statistics`). Differentiable with respect to ``images``."""
    sizes = check_shape(images, "ps_loss: images", ("N", 3, "H", "W"), dtype="float")
    check_shape(masks, "ps_loss: masks", ("N", 1, "H", "W"), sizes=sizes)
    return torch.stack(
        [
            statistics_distance(band_statistics(images[n : n + 1], masks[n : n + 1]), exemplar_stats)
            for n in range(images.shape[0])
        ]
    ).mean()


# ------------------------------------------------------------------ multi-scale raw-patch distributions
def patch_sets(
    image: torch.Tensor,
    mask: torch.Tensor | None = None,
    levels: int = PATCH_LEVELS,
    size: int = PATCH_SIZE,
    max_points: int | None = None,
    generator: torch.Generator | None = None,
) -> list[torch.Tensor]:
    """The ``patch`` loss's point sets of one image: per octave, its ``size`` x ``size`` RGB patches wholly
    on the object, flattened.

    image (1, 3, H, W); mask (1, 1, H, W) in [0, 1] or None (every pixel). Returns one (P_l, 3 size^2)
    tensor per octave while the octave is at least ``size`` px across (P_l may be 0); with
    ``max_points`` at most that many random patches per octave. Differentiable with respect to ``image``.
    """
    sizes = check_shape(image, "patch_sets: image", (1, 3, "H", "W"), dtype="float")
    check_shape(mask, "patch_sets: mask", (1, 1, "H", "W"), sizes=sizes, optional=True)
    m = torch.ones_like(image[:, :1]) if mask is None else (mask > 0.5).to(image.dtype)
    sets = []
    for level in range(levels):
        if level:
            image = F.avg_pool2d(image, 2)
            m = (F.avg_pool2d(m, 2) > _INSIDE).to(image.dtype)
        if min(image.shape[-2:]) < size:
            break
        inside = F.avg_pool2d(m, size, stride=1).flatten() > _INSIDE  # (positions,) patch wholly on the object
        patches = F.unfold(image, size)[0].t()[inside]  # (P, 3 size^2)
        if max_points is not None and patches.shape[0] > max_points:
            keep = torch.randperm(patches.shape[0], generator=generator)[:max_points].to(patches.device)
            patches = patches[keep]
        sets.append(patches)
    return sets


def exemplar_patch_sets(image: torch.Tensor, **kwargs) -> list[torch.Tensor]:
    """:func:`patch_sets` of a whole exemplar (1, 3, H, W), every patch, detached."""
    check_shape(image, "exemplar_patch_sets: image", (1, 3, None, None), dtype="float")
    with torch.no_grad():
        return [s.detach() for s in patch_sets(image, None, **kwargs)]


def patch_loss(
    images: torch.Tensor,
    masks: torch.Tensor,
    exemplar_sets: list[torch.Tensor],
    max_points: int | None = None,
    generator: torch.Generator | None = None,
    size: int = PATCH_SIZE,
) -> torch.Tensor:
    """Mean over the N images (N, 3, H, W) with masks (N, 1, H, W) of the ``patch`` distance (module
    docstring) to ``exemplar_sets`` (:func:`exemplar_patch_sets` with the same ``size``, one (Q_l, 3 size^2)
    per octave); octaves with fewer than 2 render patches count 0. Differentiable with respect to ``images``."""
    sizes = check_shape(images, "patch_loss: images", ("N", 3, "H", "W"), dtype="float")
    check_shape(masks, "patch_loss: masks", ("N", 1, "H", "W"), sizes=sizes)
    if not exemplar_sets:
        raise ValueError("patch_loss: exemplar_sets is empty (an exemplar smaller than one patch)")
    for level, b in enumerate(exemplar_sets):
        check_shape(b, f"patch_loss: exemplar_sets[{level}]", ("Q", 3 * size * size), dtype="float")
    losses = []
    for n in range(images.shape[0]):
        mine = patch_sets(images[n : n + 1], masks[n : n + 1], len(exemplar_sets), size, max_points, generator)
        losses.append(patch_distance(mine, exemplar_sets, generator))
    return torch.stack(losses).mean()


def patch_distance(
    sets: list[torch.Tensor], exemplar_sets: list[torch.Tensor], generator: torch.Generator | None = None
) -> torch.Tensor:
    """The ``patch`` distance of one set of patches per octave, (P_l, 3 size^2) flattened as :func:`patch_sets`
    flattens them (channel, then row, then column), to the exemplar's (Q_l, 3 size^2): the sum over the
    octaves of the sliced Wasserstein-2 distance, a fresh set of random directions per octave. Octaves
    with fewer than 2 patches, or beyond the shorter list, count 0. Differentiable with respect to ``sets``."""
    total = exemplar_sets[0].new_zeros(())
    for a, b in zip(sets, exemplar_sets):
        if a.shape[0] < 2:
            continue
        directions = random_directions(a.shape[1], a.shape[1], generator, a.device, a.dtype)
        total = total + sliced_wasserstein2(a, b, directions)
    return total


__all__ = [
    "GROUP_WEIGHTS",
    "NETWORK_FREE_LOSSES",
    "PATCH_LEVELS",
    "PATCH_SIZE",
    "STRUCTURE_LOSSES",
    "band_statistics",
    "check_point_sets",
    "exemplar_band_statistics",
    "exemplar_patch_sets",
    "oriented_filters",
    "patch_distance",
    "patch_loss",
    "patch_sets",
    "ps_loss",
    "quantile_resample",
    "sliced_wasserstein2",
    "statistics_distance",
    "sw_distance",
]
