"""The coarse and fine passes of :func:`mesh2tex.render.rasterize`: size bins, stencils, row spans, depth test.

Vocabulary:
  region  a rectangle of pixels with one *reference pixel* (its origin) and float32 edge and depth
          planes relative to it; a pixel's edge functions are ``fma(step_c, dc, fma(step_r, dr,
          ref))`` over its offset (dr, dc) from the reference. Regions are the triangles' pixel
          boxes, boxes over ``REGION`` pixels a side cut into ``REGION``-pixel squares.
  entry   a rectangle drawn with one dense stencil of per-pixel tests (the fine pass): the boxes
          of at most ``WHOLE`` x ``WHOLE`` pixels, which are most boxes of most meshes.
  span    the columns of one pixel row of a larger region that its triangle may cover (the coarse
          pass): exact up to a margin, so a large triangle costs its covered pixels plus a few
          per row, whatever its box; pixels well inside the span are taken without tests.
  band    edge values (scaled per edge, :func:`~mesh2tex.render.edges.band_scale`) in [-1, 1], whose
          sign float32 cannot vouch for: such pixels are set aside and decided exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

# Regions are at most REGION pixels a side (a power of two): the planes of bigger boxes are rebased
# to each REGION square so that float32 offsets stay small.
REGION = 64
# Boxes of at most WHOLE x WHOLE pixels (a power of two) get one stencil each, without a coarse
# pass: for them a few wasted pixel tests cost less than the coarse pass's per-row work.
WHOLE = 16
_BITS = WHOLE.bit_length()  # log2 of a stencil side in [1, WHOLE] is in [0, _BITS)
# Launch overhead of one bin, in candidate pixels of work: consecutive bins are merged into one
# stencil (the largest of their caps) while the padding this adds costs less than that.
_BIN_OVERHEAD_PAIRS = 16384


def columns(x: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``x[..., index]`` for a (..., N) tensor: (..., n). ``gather`` is several times faster on the
    CPU than ``index_select`` or indexing along a last dimension. A view whose last dimension is
    the rows of contiguous (N, ...) data (``movedim(0, -1)``, as the compiled rasterizer returns its
    set-ups) has its rows picked instead, without copying the whole of it."""
    if x.dim() > 1 and x.movedim(-1, 0).is_contiguous() and not x.is_contiguous():
        return x.movedim(-1, 0).index_select(0, index).movedim(0, -1)
    flat = x.reshape(-1, x.shape[-1])
    return torch.gather(flat, 1, index.expand(flat.shape[0], -1)).view(*x.shape[:-1], -1)


def size_bins(rows: torch.Tensor, cols: torch.Tensor) -> torch.Tensor:
    """Bin of each rectangle: its size rounded up to powers of two, ``row_bits * _BITS + col_bits``.

    Args:
        rows, cols: (N,) int64 sizes in [1, WHOLE].
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
    return (
        owner,
        off_r,
        off_c,
        (rows.index_select(0, owner) - off_r).clamp(max=side),
        (cols.index_select(0, owner) - off_c).clamp(max=side),
    )


def row_spans(p: torch.Tensor, rows: torch.Tensor, cols: torch.Tensor):
    """Per pixel row of each region, the columns its triangle may cover and those it surely covers.

    The edge planes are scaled so that a value outside [-1, 1] has the sign of the exact edge
    function (:func:`~mesh2tex.render.edges.band_scale`). Along a row, edge k is affine in the
    column: ``at + step_c * c`` with ``at = fma(step_r, r, ref)`` (float32, once per row), so it is at
    least -1 on one side of ``c = (-1 - at) / step_c`` and above 1 on one side of ``(1 - at) /
    step_c``. ``maybe`` takes the columns at least -1 for all edges, widened by a margin far above
    the rounding of these bounds, and ``sure`` those above 1, narrowed by it: a pixel outside
    ``maybe`` is outside the triangle and one inside ``sure`` is inside, whatever the rounding.

    Args:
        p: (12,N) float32 planes of each region, relative to its origin (rows as in :class:`Entries`).
        rows, cols: (N,) int64 region sizes.
    Returns:
        region (R,) index into N and r (R,) row offset of each row; at (3,R) float32 edge functions
        at column 0 of each row; maybe, sure: (2,R) int64 first and last column (offsets from the
        region's origin) of each range, last < first when empty.
    """
    device = rows.device
    region = torch.repeat_interleave(torch.arange(rows.numel(), device=device), rows)
    r = torch.arange(region.numel(), device=device) - (torch.cumsum(rows, 0) - rows).index_select(0, region)
    row_last = (cols - 1).index_select(0, region).float()
    at = torch.addcmul(columns(p[0:3], region), columns(p[8:11], region), r.float())
    step = columns(p[4:7], region)
    rising, falling, flat = step > 0, step < 0, step == 0
    # float32 suffices: a bound's rounding error (under 1e-4 columns within a region) is far below
    # the margin, and bounds far outside the region only need to stay outside it. Row 0: where
    # the values reach -1, row 1: where they reach 1.
    bound = (torch.tensor([[[-1.0]], [[1.0]]], device=device) - at) / step  # (2,3,R)
    lo = torch.where(rising, bound, -torch.inf).amax(1)
    hi = torch.where(falling, bound, torch.inf).amin(1)
    flat_out = torch.stack([(flat & (at < -1)).any(0), (flat & (at <= 1)).any(0)])
    (lo, sure_lo), (hi, sure_hi) = lo, torch.where(flat_out, -torch.inf, hi)
    # Never narrow a row on NaN or infinite planes: all of it is tested.
    undecided = ~torch.isfinite(at.sum(0) + step.sum(0))
    lo = torch.where(undecided, 0.0, lo).clamp(-1, 1e9)
    hi = torch.where(undecided, row_last, hi).clamp(-2, 1e9)
    sure_lo, sure_hi = sure_lo.clamp(-1, 1e9), sure_hi.clamp(-2, 1e9)
    # Column bounds to integers with a margin; infinities were clamped first.
    margin = 1e-3
    first = torch.ceil(lo - margin).clamp(min=0)
    last = torch.minimum(torch.floor(hi + margin), row_last)
    sure_first = torch.where(undecided, 1e9, torch.maximum(torch.ceil(sure_lo + margin), first))
    sure_last = torch.minimum(torch.floor(sure_hi - margin), last)
    maybe = torch.stack([first, last]).long()
    sure = torch.stack([sure_first, sure_last]).long()
    return region, r, at, maybe, sure


@dataclass
class Entries:
    """Rectangles to draw (boxes or regions), each with planes relative to its origin pixel.

    Attributes:
        params: (12,E) float32; rows 0-3: lambda_0, lambda_1, lambda_2 (each times its band scale,
            :func:`~mesh2tex.render.edges.band_scale`) and NDC z at the reference pixel; rows 4-7:
            their change per pixel step right; rows 8-11: per step down.
        base: (E,) int64 flat index into the depth buffer of the origin pixel.
        face: (E,) int64 triangle index (the low bits of the visibility key).
        setup: (E,) int64 index of the triangle's set-up (for :class:`~mesh2tex.render.edges.EdgeTest`).
    """

    params: torch.Tensor
    base: torch.Tensor
    face: torch.Tensor
    setup: torch.Tensor


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
        self.keys = torch.full((views * self.shape[1] * self.shape[2],), self.empty, dtype=torch.long, device=device)
        self.undecided = []  # (pixel, key, setup) of the pixels left to settle()

    def test(self, entries: Entries, entry, dr, dc, band=None):
        """Depth-test pixels at offsets (dr, dc) (each (n,) int64) from the reference of ``entry``.

        ``band``: (n,) bool or None, pixels whose coverage the float32 edge values leave open: they
        are set aside for :meth:`settle` instead.
        """
        q = entries.params
        z = torch.addcmul(
            torch.addcmul(q[3].index_select(0, entry), q[11].index_select(0, entry), dr.float()),
            q[7].index_select(0, entry),
            dc.float(),
        )
        pixel = entries.base.index_select(0, entry) + dr * self.row_stride + dc
        key = (((z.double() + 1) * self.depth_scale).long() << self.id_bits) | entries.face.index_select(0, entry)
        drawn = z.abs() <= 1  # near and far planes
        if band is not None:
            undecided = torch.nonzero(band & drawn).squeeze(1)
            if undecided.numel():
                self.undecided.append(
                    (
                        pixel.index_select(0, undecided),
                        key.index_select(0, undecided),
                        entries.setup.index_select(0, entry.index_select(0, undecided)),
                    )
                )
                drawn &= ~band
        key = torch.where(drawn, key, self.empty)
        self.keys.scatter_reduce_(0, pixel, key, reduce="amin", include_self=True)

    def settle(self, edges):
        """Decide the pixels set aside by :meth:`test` with the exact edge test (``edges``, an
        :class:`~mesh2tex.render.edges.EdgeTest`), all at once, and depth-test those covered."""
        if not self.undecided:
            return
        pixel, key, setup = (torch.cat(t) for t in zip(*self.undecided))
        self.undecided = []
        in_view = pixel % (self.shape[1] * self.row_stride)
        row = torch.div(in_view, self.row_stride, rounding_mode="floor")
        covered = torch.nonzero(edges.inside(setup, row, in_view % self.row_stride)).squeeze(1)
        self.keys.scatter_reduce_(
            0, pixel.index_select(0, covered), key.index_select(0, covered), reduce="amin", include_self=True
        )

    def image(self, resolution) -> torch.Tensor:
        """(B*H*W,) int64 keys without the padding."""
        H, W = resolution
        return self.keys.view(self.shape)[:, :H, :W].reshape(-1)


def draw(buffer: DepthBuffer, entries: Entries, slices, max_pairs: int):
    """Depth-test every covered pixel of the entries into ``buffer``.

    Each chunk of ``slices`` (from :func:`bin_slices`) shares a power-of-two stencil (cap_rows,
    cap_cols) and is evaluated as a dense (n, cap_rows, cap_cols) grid of edge functions, with no
    per-pixel gathers. A pixel whose smallest (scaled) edge value is above 1 is covered, below -1
    not; the few in between are left to :meth:`DepthBuffer.settle`.
    Stencil pixels outside an entry's rectangle need no test of their own: only pixels inside the
    triangle pass, and past the image's right or bottom edge they lie in the buffer's padding. The
    hits of several chunks (at most about ``max_pairs``) are depth-tested together.
    """
    device = buffer.keys.device
    hits = []  # (entry, row offset, column offset, in the band) per chunk
    pending = 0

    def flush():
        buffer.test(entries, *(torch.cat(t) for t in zip(*hits)))
        hits.clear()

    p = entries.params
    for cap_rows, cap_cols, lo, hi in slices:
        rs = torch.arange(cap_rows, device=device, dtype=torch.float32)
        cs = torch.arange(cap_cols, device=device, dtype=torch.float32)

        def plane(k):  # edge function k over the (n, rows, cols) grid
            per_row = torch.addcmul(p[k, lo:hi, None], p[k + 8, lo:hi, None], rs)
            return torch.addcmul(per_row[:, :, None], p[k + 4, lo:hi, None, None], cs)

        lam_min = torch.minimum(torch.minimum(plane(0), plane(1)), plane(2)).view(-1)
        hit = torch.nonzero(lam_min >= -1).squeeze(1)
        row_bits, col_bits = cap_rows.bit_length() - 1, cap_cols.bit_length() - 1
        entry = (hit >> (row_bits + col_bits)) + lo
        dr, dc = (hit >> col_bits) & (cap_rows - 1), hit & (cap_cols - 1)
        hits.append((entry, dr, dc, lam_min.index_select(0, hit) <= 1))
        pending += (hi - lo) * cap_rows * cap_cols
        if pending >= max_pairs:
            flush()
            pending = 0
    if hits:
        flush()


def draw_spans(buffer: DepthBuffer, regions: Entries, rows: torch.Tensor, cols: torch.Tensor, max_pairs: int):
    """Depth-test every covered pixel of the regions into ``buffer``, row by row (the coarse pass
    for large triangles): pixels in a row's ``sure`` range are taken without edge tests, the few
    others of its ``maybe`` range (:func:`row_spans`) are tested one by one (those in the band are
    left to :meth:`DepthBuffer.settle`).

    Args:
        regions: Entries of N regions.
        rows, cols: (N,) int64 region sizes.
    """
    device = rows.device
    region, r, at, maybe, sure = row_spans(regions.params, rows, cols)
    # Most rows of a sliver thinner than a pixel hold no pixel centre: drop them first.
    occupied = torch.nonzero(maybe[1] >= maybe[0]).squeeze(1)
    region, r, at = region.index_select(0, occupied), r.index_select(0, occupied), columns(at, occupied)
    maybe, sure = columns(maybe, occupied), columns(sure, occupied)
    R = region.numel()
    if R == 0:
        return
    no_sure = sure[1] < sure[0]
    left_last = torch.where(no_sure, maybe[1], sure[0] - 1)
    right_first = torch.where(no_sure, maybe[1] + 1, sure[1] + 1)
    # Three ranges per row, the tested ones first: left of sure, right of sure, sure.
    starts = torch.cat([maybe[0], right_first, sure[0]])
    counts = torch.cat([left_last - maybe[0] + 1, maybe[1] - right_first + 1, sure[1] - sure[0] + 1]).clamp(min=0)
    ends = torch.cumsum(counts, 0)
    before = ends - counts
    # Chunks of whole ranges (at most REGION pixels each) of about max_pairs pixels.
    cuts = torch.arange(max_pairs, max(max_pairs, int(ends[-1])), max_pairs, device=device)
    bounds = [0, *torch.searchsorted(ends, cuts, right=True).tolist(), 3 * R]
    step_c = regions.params[4:7]
    for a, b in zip(bounds[:-1], bounds[1:]):
        if a >= b:
            continue
        which = torch.repeat_interleave(torch.arange(a, b, device=device), counts[a:b])
        col = (
            starts.index_select(0, which)
            + torch.arange(which.numel(), device=device)
            - (before.index_select(0, which) - before[a])
        )
        row = which % R
        n_tested = int(ends[min(b, 2 * R) - 1] - before[a]) if a < 2 * R else 0
        tested_row, tested_col = row[:n_tested], col[:n_tested]
        lam = torch.addcmul(
            columns(at, tested_row), columns(step_c, region.index_select(0, tested_row)), tested_col.float()
        ).amin(0)
        passed = torch.nonzero(lam >= -1).squeeze(1)
        band = torch.cat(
            [lam.index_select(0, passed) <= 1, torch.zeros(row.numel() - n_tested, dtype=torch.bool, device=device)]
        )
        row = torch.cat([tested_row.index_select(0, passed), row[n_tested:]])
        col = torch.cat([tested_col.index_select(0, passed), col[n_tested:]])
        buffer.test(regions, region.index_select(0, row), r.index_select(0, row), col, band)
