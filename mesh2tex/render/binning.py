"""The coarse and fine passes of :func:`mesh2tex.render.rasterize`: blocks, size bins, stencils, depth test.

Vocabulary:
  region  a rectangle of pixels with one *reference pixel* (its origin) and float32 edge and depth
          planes relative to it; every pixel's edge functions are ``fma(step_c, dc, fma(step_r, dr,
          ref))`` over its offset (dr, dc) from the reference, so a pixel's coverage depends only on
          its region, not on how the region is cut up below. Regions are the triangles' pixel boxes,
          boxes over ``REGION`` pixels a side cut into ``REGION``-pixel squares.
  block   a ``BLOCK`` x ``BLOCK`` piece of a region (the coarse pass): it is dropped when one edge
          function is negative over all of it, and taken whole without edge tests when all three
          are positive over all of it, both with a safety margin far above float32 rounding.
  entry   a rectangle that gets a dense stencil of per-pixel tests (the fine pass): a small region
          whole, or a block that the coarse pass could not decide.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

# Regions are at most REGION pixels a side (a power of two): the planes of bigger boxes are rebased
# to each REGION square so that float32 offsets stay small.
REGION = 64
# Regions larger than BLOCK x BLOCK (a power of two) go through the coarse pass in blocks of this side.
BLOCK = 8
_BITS = BLOCK.bit_length()  # log2 of a stencil side in [1, BLOCK] is in [0, _BITS)
# Launch overhead of one bin, in candidate pixels of work: consecutive bins are merged into one
# stencil (the largest of their caps) while the padding this adds costs less than that.
_BIN_OVERHEAD_PAIRS = 16384
# Relative bound, far above float32 rounding (about 1.2e-7 for two fused multiply-adds), on the
# error of a pixel's edge function; the coarse pass decides a block only outside it.
_SLACK = 1e-6


def size_bins(rows: torch.Tensor, cols: torch.Tensor) -> torch.Tensor:
    """Bin of each rectangle: its size rounded up to powers of two, ``row_bits * _BITS + col_bits``.

    Args:
        rows, cols: (N,) int64 sizes in [1, BLOCK].
    Returns:
        (N,) int64 bin ids in [0, N_BINS).
    """
    # ceil(log2(size)) is the binary length of size - 1.
    row_bits = torch.frexp((rows - 1).float()).exponent.long()
    col_bits = torch.frexp((cols - 1).float()).exponent.long()
    return row_bits * _BITS + col_bits


N_BINS = _BITS * _BITS


def bin_slices(counts: list[int], max_pairs: int, start: int = 0):
    """Chunks of entries sorted by bin: ``(cap_rows, cap_cols, lo, hi)`` with at most ``max_pairs``
    candidate pixels each (at least one entry); the entries begin at index ``start``.

    Consecutive non-empty bins share one stencil when that is cheaper than a launch of their own;
    any stencil at least as large as an entry's rectangle gives the same result.
    """
    groups = []  # [row_bits, col_bits, lo, hi, own_pairs]
    for b, size in enumerate(counts):
        if size == 0:
            continue
        rb, cb = b // _BITS, b % _BITS
        own = size << (rb + cb)
        if groups:
            g = groups[-1]
            merged_rb, merged_cb = max(g[0], rb), max(g[1], cb)
            waste = ((g[3] - g[2] + size) << (merged_rb + merged_cb)) - g[4] - own
            if waste < _BIN_OVERHEAD_PAIRS:
                g[0], g[1], g[3], g[4] = merged_rb, merged_cb, start + size, g[4] + own
                start += size
                continue
        groups.append([rb, cb, start, start + size, own])
        start += size
    for rb, cb, lo, hi, _ in groups:
        step = max(1, max_pairs >> (rb + cb))
        for chunk_lo in range(lo, hi, step):
            yield 1 << rb, 1 << cb, chunk_lo, min(hi, chunk_lo + step)


def split(rows: torch.Tensor, cols: torch.Tensor, side: int):
    """Cut rectangles into pieces of at most ``side`` x ``side`` pixels, row-major from their origin.

    Args:
        rows, cols: (N,) int64 sizes, at least 1.
    Returns:
        owner (E,) index into N; off_r, off_c (E,) offsets of each piece from its rectangle's origin;
        rows, cols (E,) piece sizes.
    """
    device = rows.device
    per_col = (rows + side - 1) // side
    per_row = (cols + side - 1) // side
    n = per_col * per_row
    owner = torch.repeat_interleave(torch.arange(rows.numel(), device=device), n)
    k = torch.arange(owner.numel(), device=device) - (torch.cumsum(n, 0) - n).index_select(0, owner)
    width = per_row.index_select(0, owner)
    off_r = torch.div(k, width, rounding_mode="floor") * side
    off_c = (k % width) * side
    return (owner, off_r, off_c, (rows.index_select(0, owner) - off_r).clamp(max=side),
            (cols.index_select(0, owner) - off_c).clamp(max=side))


def classify_blocks(p: torch.Tensor, off_r, off_c, rows, cols):
    """Coarse test of blocks against their region's edge functions.

    Args:
        p: (12,N) float32 planes of each block's region (rows as in :class:`Entries`).
        off_r, off_c: (N,) int64 offset of each block's first pixel from its region's reference.
        rows, cols: (N,) int64 block sizes.
    Returns:
        outside, inside: (N,) bool. ``outside``: no pixel of the block passes the edge tests;
        ``inside``: a full BLOCK x BLOCK block all of whose pixels pass them. Neither: test each pixel.
    """
    p = p.double()
    r_lo, c_lo = off_r.double(), off_c.double()
    r_hi, c_hi = r_lo + (rows - 1), c_lo + (cols - 1)
    outside = torch.zeros_like(off_r, dtype=torch.bool)
    inside = (rows == BLOCK) & (cols == BLOCK)
    for k in range(3):  # an affine function's extremes over a rectangle are at its corners
        r1, r2 = p[k + 8] * r_lo, p[k + 8] * r_hi
        c1, c2 = p[k + 4] * c_lo, p[k + 4] * c_hi
        top = p[k] + torch.maximum(r1, r2) + torch.maximum(c1, c2)
        bottom = p[k] + torch.minimum(r1, r2) + torch.minimum(c1, c2)
        slack = _SLACK * (p[k].abs() + torch.maximum(r1.abs(), r2.abs()) + torch.maximum(c1.abs(), c2.abs()))
        outside |= top < -slack  # NaN and inf planes are never decided here
        inside &= (bottom >= slack) & torch.isfinite(slack)
    return outside, inside & ~outside


@dataclass
class Entries:
    """Rectangles to draw, each relative to its region's reference pixel.

    Attributes:
        params: (12,E) float32; rows 0-3: lambda_0, lambda_1, lambda_2 and NDC z at the reference
            pixel; rows 4-7: their change per pixel step right; rows 8-11: per step down.
        base: (E,) int64 flat index into the depth buffer of the reference pixel.
        face: (E,) int64 triangle index (the low bits of the visibility key).
        off_r, off_c: (E,) int64 offset of the entry's first pixel from the reference; None for 0.
    """

    params: torch.Tensor
    base: torch.Tensor
    face: torch.Tensor
    off_r: torch.Tensor | None = None
    off_c: torch.Tensor | None = None


class DepthBuffer:
    """Visibility keys of a padded (B, H + pad_r, W + pad_c) image: quantised NDC depth in the high
    bits, triangle index in the low bits, so that ``amin`` keeps the nearest, then the lowest index.

    Padding on the right and bottom keeps stencils that run past the image edge inside the buffer.
    """

    def __init__(self, views: int, resolution, pad, triangles: int, device):
        H, W = resolution
        self.shape = (views, H + pad[0], W + pad[1])
        self.row_stride = self.shape[2]
        self.id_bits = max(1, int(triangles).bit_length())
        self.depth_scale = 0.5 * float((1 << min(62 - self.id_bits, 40)) - 1)
        self.empty = torch.iinfo(torch.long).max
        self.keys = torch.full((views * self.shape[1] * self.shape[2],), self.empty, dtype=torch.long,
                               device=device)

    def test(self, entries: Entries, entry, dr, dc):
        """Depth-test pixels at offsets (dr, dc) (each (n,) int64) from the reference of ``entry``."""
        q = entries.params
        z = torch.addcmul(torch.addcmul(q[3].index_select(0, entry), q[11].index_select(0, entry), dr.float()),
                          q[7].index_select(0, entry), dc.float())
        pixel = entries.base.index_select(0, entry) + dr * self.row_stride + dc
        key = (((z.double() + 1) * self.depth_scale).long() << self.id_bits) | entries.face.index_select(0, entry)
        key = torch.where(z.abs() <= 1, key, self.empty)  # near and far planes
        self.keys.scatter_reduce_(0, pixel, key, reduce="amin", include_self=True)

    def image(self, resolution) -> torch.Tensor:
        """(B*H*W,) int64 keys without the padding."""
        H, W = resolution
        return self.keys.view(self.shape)[:, :H, :W].reshape(-1)


def draw(buffer: DepthBuffer, entries: Entries, slices, max_pairs: int, inside=(0, 0)):
    """Depth-test every covered pixel of the entries into ``buffer``.

    Each chunk of ``slices`` (from :func:`bin_slices`) shares a power-of-two stencil (cap_rows,
    cap_cols) and is evaluated as a dense (n, cap_rows, cap_cols) grid of edge functions, with no
    per-pixel gathers. Stencil pixels outside an entry's rectangle need no test of their own: only
    pixels inside the triangle pass, and they belong to the same region (same planes, same result)
    or lie in the buffer's padding. Entries ``inside[0]:inside[1]`` are full blocks taken without
    edge tests. The hits of several chunks (at most about ``max_pairs``) are depth-tested together.
    """
    device = buffer.keys.device
    hits = []  # (entry, row offset, column offset) per chunk
    pending = 0

    def flush():
        buffer.test(entries, *(torch.cat(t) for t in zip(*hits)))
        hits.clear()

    p = entries.params
    for cap_rows, cap_cols, lo, hi in slices:
        row_steps = torch.arange(cap_rows, device=device)
        col_steps = torch.arange(cap_cols, device=device)
        if entries.off_r is None:
            rs, cs = row_steps.float(), col_steps.float()
        else:  # per-entry offsets from the reference: the same products as a region drawn whole
            rs = (entries.off_r[lo:hi, None] + row_steps).float()
            cs = (entries.off_c[lo:hi, None] + col_steps).float()[:, None, :]

        def plane(k):  # edge function k over the (n, rows, cols) grid
            per_row = torch.addcmul(p[k, lo:hi, None], p[k + 8, lo:hi, None], rs)
            return torch.addcmul(per_row[:, :, None], p[k + 4, lo:hi, None, None], cs)

        lam_min = torch.minimum(torch.minimum(plane(0), plane(1)), plane(2))
        hit = torch.nonzero(lam_min.view(-1) >= 0).squeeze(1)
        row_bits, col_bits = cap_rows.bit_length() - 1, cap_cols.bit_length() - 1
        entry = (hit >> (row_bits + col_bits)) + lo
        dr, dc = (hit >> col_bits) & (cap_rows - 1), hit & (cap_cols - 1)
        if entries.off_r is not None:
            dr, dc = dr + entries.off_r.index_select(0, entry), dc + entries.off_c.index_select(0, entry)
        hits.append((entry, dr, dc))
        pending += (hi - lo) * cap_rows * cap_cols
        if pending >= max_pairs:
            flush()
            pending = 0
    # Full blocks: every pixel is a hit.
    step = max(1, max_pairs // (BLOCK * BLOCK))
    pixel = torch.arange(BLOCK * BLOCK, device=device)
    for lo in range(inside[0], inside[1], step):
        hi = min(inside[1], lo + step)
        entry = torch.arange(lo, hi, device=device).repeat_interleave(BLOCK * BLOCK)
        local = pixel.repeat(hi - lo)
        hits.append((entry, entries.off_r.index_select(0, entry) + local // BLOCK,
                     entries.off_c.index_select(0, entry) + local % BLOCK))
        pending += (hi - lo) * BLOCK * BLOCK
        if pending >= max_pairs:
            flush()
            pending = 0
    if hits:
        flush()
