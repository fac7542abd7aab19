"""A triangle rasteriser in pure JAX with static shapes, shared by the cloth camera and the coverage metric.

Coordinates are in pixel units of an image of ``height x width`` pixels: a point is ``(x, y)`` with ``x``
along the columns (to the right) and ``y`` along the rows (down); pixel ``(r, c)`` covers
``[c, c + 1) x [r, r + 1)`` and is sampled at its centre ``(c + 0.5, r + 0.5)``. A pixel belongs to a
triangle when its centre is inside it or on its boundary (an exact edge-function test, either winding;
degenerate triangles of zero area cover nothing).

Each triangle is tested on a fixed ``window x window`` block of pixels whose first column and row are the
first whose centres are not left of (above) the triangle's bounding box: ``c0 = ceil(min x - 0.5)``,
``r0 = ceil(min y - 0.5)``. So the cost is ``T * window**2`` candidate pixels whatever the triangles look
like, and shapes are static. The window covers all of a triangle's pixels when

    window >= floor(e) + 1,   e = the larger of the triangle's x and y bounding-box extents, in pixels,

(:func:`window_for` returns that for an extent bound). Pixels of a triangle whose projected extent is larger
are **missed** (only the window's pixels are tested; those beyond its right or bottom side stay empty or
show what lies behind), so callers derive the window from a static bound on the triangles' size: for a
grid mesh, the longest edge of a triangle is the cell diagonal ``sqrt(2) * spacing`` times the stretch,
and any triangle's extent along an axis is at most its longest edge (times the projection's scale).

Visibility is a z-buffer done by one scatter-min of a packed int32 key per candidate pixel: the high bits
hold the depth (the per-vertex ``z`` interpolated linearly in image space at the pixel centre, quantised
uniformly over ``z_range``, smaller is nearer), the low ``ceil(log2(T))`` bits the triangle id. The nearest
triangle wins, and among triangles whose depths quantise to the same value the lowest id does. Integer
min is exact and order-independent, so results are deterministic and the same under ``vmap`` for a batch
of one or of many. The depth resolution is ``(z_range[1] - z_range[0]) / 2**(31 - id_bits)``; depths
outside ``z_range`` are clipped into it (they still draw, but tie among themselves).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

_EMPTY = np.int32(np.iinfo(np.int32).max)
_MIN_DEPTH_BITS = 8


class Raster(NamedTuple):
    """What :func:`rasterize` returns for an image of ``height x width`` pixels.

    tri_id: int32 (height, width): the visible triangle at each pixel, -1 where none covers it.
    bary: float32 (height, width, 3): image-space barycentric coordinates of the pixel centre in that
      triangle (weights of its vertices 0, 1, 2; they sum to 1), zeros where ``tri_id`` is -1.
    """

    tri_id: jax.Array
    bary: jax.Array


def window_for(extent: float) -> int:
    """The window (pixels per side) that holds every pixel of a triangle whose bounding box is at most
    ``extent`` pixels along x and along y: ``floor(extent) + 1``."""
    if not extent >= 0:
        raise ValueError(f"triangle extent must be non-negative, got {extent}")
    return int(math.floor(extent)) + 1


def id_bits(num_triangles: int) -> int:
    """Bits of the packed z-buffer key that hold the triangle id (the rest, ``31 - id_bits``, hold depth)."""
    return max(1, int(num_triangles - 1).bit_length())


def edge_functions(p, a, b, c):
    """Edge functions of point(s) ``p`` (..., 2) against triangle(s) ``a, b, c`` (..., 2): twice the signed
    areas of ``(b, c, p)``, ``(c, a, p)``, ``(a, b, p)`` (the unnormalised barycentric weights of a, b, c).

    Each is evaluated with its edge's endpoints in a canonical order (then negated if swapped), so two
    triangles sharing an edge get exactly opposite values there in floating point: a pixel centre on or
    near a shared edge is never outside both (no cracks between the triangles of a mesh).
    """

    def edge(o, q):
        swap = (q[..., 0] < o[..., 0]) | ((q[..., 0] == o[..., 0]) & (q[..., 1] < o[..., 1]))
        lo = jnp.where(swap[..., None], q, o)
        hi = jnp.where(swap[..., None], o, q)
        e = (hi[..., 0] - lo[..., 0]) * (p[..., 1] - lo[..., 1]) - (hi[..., 1] - lo[..., 1]) * (p[..., 0] - lo[..., 0])
        return jnp.where(swap, -e, e)

    return edge(b, c), edge(c, a), edge(a, b)


def inside(w0, w1, w2):
    """Inside or on the boundary, either winding, from the three edge functions; false for zero area."""
    area = w0 + w1 + w2
    pos = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
    neg = (w0 <= 0) & (w1 <= 0) & (w2 <= 0)
    return (pos | neg) & (area != 0)


def _candidates(xy, shape, window, valid):
    """Every triangle's window of candidate pixels.

    Returns (flat pixel index int32 (T, w, w), out of range where the pixel is off the image, not covered
    by the triangle or the triangle is not valid; the edge functions, each float32 (T, w, w)).
    """
    height, width = shape
    xy = jnp.asarray(xy, jnp.float32)
    if valid is None:
        valid = jnp.ones(xy.shape[0], bool)
    valid = valid & jnp.all(jnp.isfinite(xy), axis=(1, 2))
    xy = jnp.where(valid[:, None, None], xy, 0.0)
    lo = jnp.min(xy, axis=1)  # (T, 2)
    # First pixel whose centre is not before the box; clipped so far-off triangles stay far off without
    # overflowing int32 (their windows then lie wholly outside the image).
    start = jnp.ceil(lo - 0.5)
    start = jnp.stack([jnp.clip(start[:, 0], -window - 1, width + 1),
                       jnp.clip(start[:, 1], -window - 1, height + 1)], -1).astype(jnp.int32)
    offs = jnp.arange(window, dtype=jnp.int32)
    cols = start[:, 0, None, None] + offs[None, None, :]  # (T, 1, w)
    rows = start[:, 1, None, None] + offs[None, :, None]  # (T, w, 1)
    centre = jnp.stack(jnp.broadcast_arrays(cols.astype(jnp.float32) + 0.5, rows.astype(jnp.float32) + 0.5), -1)
    a, b, c = (xy[:, k, None, None, :] for k in range(3))
    w0, w1, w2 = edge_functions(centre, a, b, c)
    hit = inside(w0, w1, w2) & valid[:, None, None]
    hit = hit & (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height)
    flat = jnp.where(hit, rows * width + cols, height * width)  # height * width: dropped by the scatter
    return flat, (w0, w1, w2)


def rasterize(xy, z, shape: tuple[int, int], window: int, z_range=(0.0, 1.0), valid=None) -> Raster:
    """Draws triangles with a z-buffer: the nearest (smallest ``z``) triangle at each pixel centre.

    Args:
      xy: float (T, 3, 2) triangle vertices in pixel coordinates (x: columns, y: rows).
      z: float (T, 3) per-vertex depth key, interpolated linearly in image space; smaller is nearer.
        Pass e.g. zeros when only coverage matters (ties go to the lowest triangle id).
      shape: static ``(height, width)`` of the image in pixels.
      window: static pixels per side of each triangle's test block; see the module doc (``window_for``).
      z_range: ``(lo, hi)`` over which ``z`` is quantised (floats or traced scalars).
      valid: optional bool (T,); triangles that are false (and any with non-finite vertices) are not drawn.

    Returns:
      :class:`Raster` with ``tri_id`` int32 (height, width) and ``bary`` float32 (height, width, 3).
    """
    height, width = int(shape[0]), int(shape[1])
    window = int(window)
    num_tri = int(xy.shape[0])
    bits = id_bits(num_tri)
    depth_bits = 31 - bits
    if depth_bits < _MIN_DEPTH_BITS:
        raise ValueError(f"{num_tri} triangles leave only {depth_bits} bits of depth in the int32 z-buffer key")
    xy = jnp.asarray(xy, jnp.float32)
    z = jnp.asarray(z, jnp.float32)
    flat, (w0, w1, w2) = _candidates(xy, (height, width), window, valid)

    area = w0 + w1 + w2
    safe = jnp.where(area == 0, 1.0, area)
    zc = (w0 * z[:, 0, None, None] + w1 * z[:, 1, None, None] + w2 * z[:, 2, None, None]) / safe
    lo, hi = (jnp.asarray(v, jnp.float32) for v in z_range)
    levels = (1 << depth_bits) - 2  # the largest key stays below _EMPTY
    frac = jnp.clip((zc - lo) / (hi - lo), 0.0, 1.0)
    frac = jnp.where(jnp.isnan(frac), 1.0, frac)
    quant = jnp.round(frac * levels).astype(jnp.int32)
    ids = jnp.arange(num_tri, dtype=jnp.int32)[:, None, None]
    key = (quant << bits) | ids

    zbuf = jnp.full(height * width, _EMPTY, jnp.int32)
    zbuf = zbuf.at[flat.reshape(-1)].min(key.reshape(-1), mode="drop")
    tri = jnp.where(zbuf == _EMPTY, -1, zbuf & ((1 << bits) - 1))

    # Barycentric coordinates of each pixel centre in its winning triangle (recomputed, cheaper than
    # carrying them through the scatter).
    r, c = jnp.divmod(jnp.arange(height * width, dtype=jnp.int32), width)
    centre = jnp.stack([c.astype(jnp.float32) + 0.5, r.astype(jnp.float32) + 0.5], -1)
    v = xy[jnp.maximum(tri, 0)]  # (P, 3, 2)
    e0, e1, e2 = edge_functions(centre, v[:, 0], v[:, 1], v[:, 2])
    tot = e0 + e1 + e2
    bary = jnp.stack([e0, e1, e2], -1) / jnp.where(tot == 0, 1.0, tot)[:, None]
    bary = jnp.where((tri >= 0)[:, None], bary, 0.0)
    return Raster(tri.reshape(height, width), bary.reshape(height, width, 3))


def covered(xy, shape: tuple[int, int], window: int, valid=None) -> jax.Array:
    """bool (height, width): pixels whose centre some triangle covers (no depth, no ids: the cheap path).

    Same arguments and the same window rule as :func:`rasterize`; ``covered(...) == (rasterize(...).tri_id
    >= 0)``.
    """
    height, width = int(shape[0]), int(shape[1])
    flat, _ = _candidates(jnp.asarray(xy, jnp.float32), (height, width), int(window), valid)
    grid = jnp.zeros(height * width, bool).at[flat.reshape(-1)].set(True, mode="drop")
    return grid.reshape(height, width)
