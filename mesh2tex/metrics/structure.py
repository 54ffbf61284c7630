"""A judge of texture structure on renders, built from none of the training losses.

Three measures of the object's pixels of a set of renders, each also taken of the exemplar image so
that a row reads against the exemplar's own figure:

**Patch distance** (``swd``): the sliced Wasserstein-1 distance (x1000) between raw 7 x 7 RGB
    patches of the renders and of the exemplar, at ``levels`` scales (2 x 2 area averages between
    them). Only patches wholly on the object count (no silhouette, no background); both sets are
    normalised by the exemplar's per-dimension mean and deviation, cut to the same count at random
    and projected on ``projections`` fixed random directions (a seed: rows of one table share them).
    Raw pixels keep colour, contrast, orientation and period together; no network is involved.
    The exemplar's patches are taken from its eight 90-degree rotations and mirror images: a
    surface has no global up, and a pattern on a sphere or a chair shows every orientation of it
    (without them, the exemplar's own stripes painted on a sphere score no better than noise).

**Gradient orientation** in square windows wholly on the object (``window`` px, stride half of it),
    from the luminance's central-difference gradients g = (gx, gy) with energy e = |g|^2 and
    orientation phi = atan2(gy, gx) mod 180 degrees; windows with almost no energy (flat colour)
    are left out.

    coherence  |sum e exp(2 i phi)| / sum e per window (the structure tensor's coherence), averaged
               over the windows: 1 for stripes (one direction), near 0 for checks or noise.
    ratio      the energy within +-17 degrees of the window's strongest direction and within
               +-17 degrees of its perpendicular (a 16-bin histogram, 3 bins each side), weaker over
               stronger, averaged: near 1 for checks (two perpendicular edge families), near 0
               for stripes. (Isotropic noise also scores near 1: read it with the other measures.)
    direction  the energy-weighted mean gradient orientation of the set (radians in [0, pi)),
               for tests and figures.

**Regularity** (``regularity``): how strongly the luminance repeats itself, locally. In each
    64 px window at least half on the object (stride 32 px), the autocorrelation of the object's
    luminance (mean removed, over the pairs of object pixels at each lag; lags with fewer than a
    quarter of the window's pairs are left out), divided by its value at lag 0; beyond its central
    lobe (from the first ring of lags whose mean falls to 0) out to ``max_lag`` px, its highest
    value; averaged over the textured windows. Windows, not the whole render: a pattern wrapped on
    a curved surface turns from place to place, and a whole-image autocorrelation would average
    its repeats away. A repeat of the pattern within ``max_lag`` (32 px) shows as a second peak:
    near 1 for a crisp checker or stripes seen flat, lower where a surface foreshortens them; near 0
    for blotches or noise, whose autocorrelation falls and stays down (0 where it never falls to 0
    within ``max_lag``). Unlike the orientation ratio it does not mistake isotropic blotches for
    checks, and unlike the patch distance it does not prefer crisp blotches of the right colours to
    a soft checker. It is a property, not a distance: a blurred copy of the pattern, or a more
    uniform one than the oracle's, can score above the oracle.

**Period** (``period``, pixels): the peak of the radially averaged power spectrum of the luminance,
    pooled over ``patch``-px windows wholly on the object (mean removed, Hann window, zero-padded
    to four times the side; each ring's mean power times its radius, the power per unit of radial
    frequency), with a parabola through the peak bin and its neighbours; frequencies below one
    cycle per ``max_period`` px are left out (the window's own leakage lives there). Within about
    5% for periods up to half the window; longer ones read short.

Conventions: images (N, 3, H, W) and the exemplar (1, 3, h, w) in [0, 1]; masks (N, 1, H, W) object
where above 0.5. The renders should show the pattern at the exemplar's pixel scale (the same
texture pixels per image pixel), or the period and distance compare different things.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape
from mesh2tex.metrics.spectrum import object_patches
from mesh2tex.metrics.swd import sliced_wasserstein

_FLAT = 1e-5  # mean gradient energy per pixel below which a window counts as untextured ((1/255)^2 is 1.5e-5)
_FLAT_VARIANCE = 1e-8  # windowed luminance variance below which a set has no texture (8-bit steps give 1e-6 and more)
BINS = 16  # orientation histogram bins over 180 degrees
HALF_WIDTH = 1  # bins each side of a direction counted as "that direction" (3 bins: 33.75 degrees)


@dataclass(frozen=True)
class StructureScores:
    """The judge's figures of one set: ``swd`` (NaN where no exemplar was given), ``coherence``,
    ``ratio`` and ``direction`` (NaN with no textured window), ``period`` (NaN with no patch or
    no power), ``windows`` (textured orientation windows counted), ``regularity`` (NaN with no texture)."""

    swd: float
    coherence: float
    ratio: float
    direction: float
    period: float
    windows: int
    regularity: float = math.nan

    def as_dict(self) -> dict:
        return asdict(self)


def luminance(images: torch.Tensor) -> torch.Tensor:
    """(N, 3, H, W) RGB in [0, 1] -> (N, 1, H, W) Rec. 601 luma."""
    check_shape(images, "luminance: images", ("N", 3, "H", "W"), dtype="float")
    weights = torch.tensor([0.299, 0.587, 0.114], dtype=images.dtype, device=images.device)
    return (images * weights[:, None, None]).sum(1, keepdim=True)


def _check(function: str, images: torch.Tensor, masks: torch.Tensor | None) -> torch.Tensor:
    """``masks`` (ones for None) once images (N, 3, H, W) float and masks (N, 1, H, W) or None are checked."""
    sizes = check_shape(images, f"{function}: images", ("N", 3, "H", "W"), dtype="float")
    check_shape(masks, f"{function}: masks", ("N", 1, "H", "W"), sizes=sizes, optional=True)
    return torch.ones_like(images[:, :1]) if masks is None else masks


def orientation_windows(
    images: torch.Tensor, masks: torch.Tensor | None = None, window: int = 24
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per textured window, the energy-weighted orientation histogram and the doubled-angle sum.

    images (N, 3, H, W) in [0, 1]; masks (N, 1, H, W) or None. Returns histograms (M, BINS) of
    gradient energy per orientation bin (bin k covers [k, k + 1) * 180 / BINS degrees) and the
    complex doubled-angle sums (M,) complex128, for the M windows wholly on the object (eroded by the
    gradient's one-pixel reach) whose mean energy is above the flat threshold.
    """
    masks = _check("orientation_windows", images, masks)
    y = luminance(images.double())
    gx = torch.zeros_like(y)
    gy = torch.zeros_like(y)
    gx[..., :, 1:-1] = (y[..., :, 2:] - y[..., :, :-2]) / 2
    gy[..., 1:-1, :] = (y[..., 2:, :] - y[..., :-2, :]) / 2
    # A gradient counts only where its whole 3 x 3 neighbourhood is on the object (and off the image border).
    inner = F.pad(masks.double()[..., 1:-1, 1:-1], (1, 1, 1, 1))
    eroded = (F.avg_pool2d(inner, 3, stride=1, padding=1) > 1 - 1e-6).double()
    patches, _ = object_patches(torch.cat([gx, gy], 1), eroded, window)
    if len(patches) == 0:
        return torch.zeros(0, BINS, dtype=torch.float64), torch.zeros(0, dtype=torch.complex128)
    gx, gy = patches[:, 0].double().flatten(1), patches[:, 1].double().flatten(1)
    energy = gx.square() + gy.square()
    keep = energy.mean(1) > _FLAT
    gx, gy, energy = gx[keep], gy[keep], energy[keep]
    phi = torch.remainder(torch.atan2(gy, gx), math.pi)
    index = (phi / math.pi * BINS).long().clamp(0, BINS - 1)
    histograms = torch.zeros(len(energy), BINS, dtype=torch.float64).scatter_add_(1, index, energy)
    doubled = (energy * torch.exp(2j * phi)).sum(1)
    return histograms, doubled


def orientation_scores(histograms: torch.Tensor, doubled: torch.Tensor) -> tuple[float, float, float]:
    """(mean coherence, mean weaker/stronger perpendicular energy ratio, set's mean direction in radians)
    of :func:`orientation_windows`'s output (histograms (M, BINS), doubled (M,)); NaNs when there is no window."""
    sizes = check_shape(histograms, "orientation_scores: histograms", ("M", BINS), dtype="float")
    check_shape(doubled, "orientation_scores: doubled", ("M",), sizes=sizes)
    if len(histograms) == 0:
        return math.nan, math.nan, math.nan
    total = histograms.sum(1)
    coherence = (doubled.abs() / total).mean()
    # Energy within HALF_WIDTH bins of each direction (circular over 180 degrees).
    near = sum(torch.roll(histograms, shift, dims=1) for shift in range(-HALF_WIDTH, HALF_WIDTH + 1))
    strongest = near.argmax(1)
    perpendicular = (strongest + BINS // 2) % BINS
    rows = torch.arange(len(near))
    ratio = (near[rows, perpendicular] / near[rows, strongest].clamp_min(1e-30)).mean()
    direction = float(torch.remainder(torch.angle(doubled.sum()) / 2, math.pi))
    return float(coherence), float(ratio), direction


def spectrum_period(
    images: torch.Tensor, masks: torch.Tensor | None = None, patch: int = 32, max_period: float = 28.0
) -> float:
    """The dominant period in pixels of the luminance of the object's ``patch``-px windows (module
    docstring); NaN with no window or no power. images (N, 3, H, W) in [0, 1]; masks (N, 1, H, W) or None."""
    masks = _check("spectrum_period", images, masks)
    patches, _ = object_patches(luminance(images.double()), masks, patch)
    if len(patches) == 0:
        return math.nan
    x = patches[:, 0].double()
    hann = torch.hann_window(patch, periodic=False, dtype=torch.float64)
    window = hann[:, None] * hann[None, :]
    x = (x - (x * window).sum((-2, -1), keepdim=True) / window.sum()) * window
    if float(x.square().mean()) < _FLAT_VARIANCE:  # a flat colour: float rounding has no period
        return math.nan
    size = 4 * patch  # zero padding: a finer sampling of the same (window-smoothed) spectrum
    power = torch.fft.fft2(x, s=(size, size)).abs().square().sum(0)  # pooled (size, size)
    f = torch.fft.fftfreq(size, dtype=torch.float64)
    radius = torch.sqrt(f[:, None] ** 2 + f[None, :] ** 2) * size  # in bins of 1 / size cycles per pixel
    ring = radius.round().long()
    count = size // 2
    radial = torch.zeros(count + 1, dtype=torch.float64).scatter_add_(
        0, ring.clamp(max=count).flatten(), power.flatten()
    )
    rings = torch.zeros(count + 1, dtype=torch.float64).scatter_add_(
        0, ring.clamp(max=count).flatten(), torch.ones_like(power).flatten()
    )
    # Mean power per ring times its radius: the power per unit of radial frequency (a peak's own
    # radius, where the plain ring mean would favour the smaller rings).
    radial = radial / rings.clamp_min(1) * torch.arange(count + 1, dtype=torch.float64)
    lowest = math.ceil(size / max_period)
    radial[:lowest] = 0
    radial[count] = 0
    k = int(radial.argmax())
    if radial[k] <= 1e-12 * patches.shape[0]:  # no texture: rounding noise of a flat colour
        return math.nan
    # A parabola through the peak and its neighbours places it between bins.
    a, b, c = float(radial[k - 1]) if k > lowest else float(radial[k]), float(radial[k]), float(radial[k + 1])
    offset = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) < 0 else 0.0
    return size / (k + max(-0.5, min(0.5, offset)))


def regularity(images: torch.Tensor, masks: torch.Tensor | None = None, window: int = 64, max_lag: int = 32) -> float:
    """The height of the luminance's strongest repeat within ``max_lag`` px (module docstring), averaged over
    the textured ``window``-px windows (stride half a window) at least half on the object: in [-1, 1], 0 for a
    window whose autocorrelation never falls to 0; NaN with no such window. images (N, 3, H, W) in [0, 1];
    masks (N, 1, H, W) or None."""
    masks = _check("regularity", images, masks)
    if min(images.shape[-2:]) < window:
        return math.nan
    y = luminance(images.double())
    m = (masks > 0.5).double()
    stride = window // 2
    lum = F.unfold(y, window, stride=stride).transpose(1, 2).reshape(-1, window, window)
    on = F.unfold(m, window, stride=stride).transpose(1, 2).reshape(-1, window, window)
    count = on.sum((1, 2))
    keep = count >= 0.5 * window * window
    lum, on, count = lum[keep], on[keep], count[keep]
    x = (lum - (lum * on).sum((1, 2), keepdim=True) / count.clamp_min(1)[:, None, None]) * on
    textured = x.square().sum((1, 2)) / count.clamp_min(1) > _FLAT_VARIANCE
    x, on = x[textured], on[textured]
    if len(x) == 0:
        return math.nan
    size = (2 * window, 2 * window)  # zero padding: every lag's products are of pixel pairs inside the window
    products = torch.fft.ifft2(torch.fft.fft2(x, s=size).abs().square()).real  # (M, 2w, 2w)
    pairs = torch.fft.ifft2(torch.fft.fft2(on, s=size).abs().square()).real
    valid = pairs > 0.25 * pairs[:, :1, :1]  # lags with at least a quarter of the window's pairs
    correlation = torch.where(valid, products / pairs.clamp_min(1), torch.zeros_like(products))
    correlation = correlation / correlation[:, :1, :1]
    lag = torch.fft.fftfreq(size[0], 1 / size[0], dtype=torch.float64)
    radius = torch.sqrt(lag[:, None] ** 2 + lag[None, :] ** 2)
    ring = radius.round().long()
    scores = []
    for c, v in zip(correlation, valid):
        lobe_end = None
        for r in range(1, max_lag + 1):
            here = (ring == r) & v
            if here.any() and float(c[here].mean()) <= 0:
                lobe_end = r
                break
        beyond = v & (radius >= (lobe_end or max_lag + 1)) & (radius <= max_lag)
        scores.append(float(c[beyond].max()) if beyond.any() else 0.0)
    return sum(scores) / len(scores)


def patch_swd(
    images: torch.Tensor,
    masks: torch.Tensor | None,
    exemplar: torch.Tensor,
    levels: int = 3,
    patch: int = 7,
    projections: int = 256,
    seed: int = 0,
    most: int = 4096,
    turns: bool = True,
    exemplar_masks: torch.Tensor | None = None,
) -> float:
    """The patch distance x 1000 (module docstring), averaged over the levels where both sides have at
    least 32 patches; NaN where none has. images (N, 3, H, W) and exemplar (1, 3, h, w) in [0, 1];
    masks (N, 1, H, W) or None. ``most``: patches per side and level at most (random); ``turns``:
    the exemplar in its eight orientations (for renders of meshes), else only as it is (for flat
    images that keep the exemplar's orientation). ``exemplar`` may be a set of renders (M, 3, h, w)
    with ``exemplar_masks`` (M, 1, h, w): the reference's patches are then its object's alone (the
    renders of the oracle, compared with ``turns=False``)."""
    masks = _check("patch_swd", images, masks).double()
    sizes = check_shape(exemplar, "patch_swd: exemplar", ("M", 3, "h", "w"), dtype="float")
    check_shape(exemplar_masks, "patch_swd: exemplar_masks", ("M", 1, "h", "w"), sizes=sizes, optional=True)
    reference_masks = torch.ones_like(exemplar[:, :1]) if exemplar_masks is None else exemplar_masks
    reference_masks = reference_masks.double()
    generator = torch.Generator().manual_seed(seed)
    images, reference = images.double(), exemplar.double()
    values = []
    for level in range(levels):
        if level:
            images, reference = F.avg_pool2d(images, 2), F.avg_pool2d(reference, 2)
            masks = (F.avg_pool2d(masks, 2) > 1 - 1e-6).double()  # a coarse pixel is on the object when all four are
            reference_masks = (F.avg_pool2d(reference_masks, 2) > 1 - 1e-6).double()
        if min(images.shape[-2:] + reference.shape[-2:]) < patch:
            break
        mine, _ = object_patches(images, masks, patch, stride=1)
        both = torch.cat([reference, reference_masks], 1)
        turned = (
            torch.cat([torch.rot90(r, k, (-2, -1)) for r in (both, both.flip(-1)) for k in range(4)]) if turns else both
        )
        theirs, _ = object_patches(turned[:, :3], turned[:, 3:], patch, stride=1)
        n = min(len(mine), len(theirs), most)
        if n < 32:
            continue
        mine = mine.flatten(1)[torch.randperm(len(mine), generator=generator)[:n]].double()
        theirs = theirs.flatten(1)[torch.randperm(len(theirs), generator=generator)[:n]].double()
        mean, std = theirs.mean(0), theirs.std(0).clamp_min(1e-3)
        values.append(1000.0 * sliced_wasserstein((theirs - mean) / std, (mine - mean) / std, projections, generator))
    return sum(values) / len(values) if values else math.nan


def structure_scores(
    images: torch.Tensor,
    masks: torch.Tensor | None = None,
    exemplar: torch.Tensor | None = None,
    window: int = 24,
    patch: int = 32,
    seed: int = 0,
) -> StructureScores:
    """All of the judge's figures for a set of renders (module docstring).

    images (N, 3, H, W) in [0, 1]; masks (N, 1, H, W) or None (whole images); exemplar (1, 3, h, w)
    in [0, 1] or None (then ``swd`` is NaN), at the renders' pixel scale.
    """
    masks = _check("structure_scores", images, masks)
    check_shape(exemplar, "structure_scores: exemplar", (None, 3, None, None), dtype="float", optional=True)
    histograms, doubled = orientation_windows(images, masks, window)
    coherence, ratio, direction = orientation_scores(histograms, doubled)
    distance = math.nan
    if exemplar is not None:
        distance = patch_swd(images, masks, exemplar, seed=seed)
    return StructureScores(
        swd=float(distance),
        coherence=coherence,
        ratio=ratio,
        direction=direction,
        period=spectrum_period(images, masks, patch),
        windows=len(histograms),
        regularity=regularity(images, masks),
    )


__all__ = [
    "BINS",
    "StructureScores",
    "luminance",
    "orientation_scores",
    "patch_swd",
    "orientation_windows",
    "regularity",
    "spectrum_period",
    "structure_scores",
]
