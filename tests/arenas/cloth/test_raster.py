"""The shared triangle rasteriser: exact coverage, z-buffer visibility, windows, determinism under vmap."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena.arenas.cloth import raster

SHAPE = (24, 32)  # height, width


def brute_force(xy, shape):
    """bool (T, H, W): float64 numpy inside test of every pixel centre in every triangle, and bool (T, H, W):
    the pixel centre is not on (within 1e-4 pixels of) the triangle's edges, where float32 may differ."""
    h, w = shape
    r, c = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    xy = np.asarray(xy, np.float64)[:, :, None, None, :]
    a, b, d = xy[:, 0], xy[:, 1], xy[:, 2]

    def cross(o, q):
        return (q[..., 0] - o[..., 0]) * (r - o[..., 1]) - (q[..., 1] - o[..., 1]) * (c - o[..., 0])

    e = np.stack([cross(b, d), cross(d, a), cross(a, b)])  # (3, T, H, W)
    inside = (np.all(e >= 0, 0) | np.all(e <= 0, 0)) & (e.sum(0) != 0)
    length = np.linalg.norm(np.roll(xy, -1, axis=1) - np.roll(xy, 1, axis=1), axis=-1)  # edge opposite each vertex
    clear = np.all(np.abs(e) > 1e-4 * np.moveaxis(length, 1, 0), axis=0)
    return inside, clear


def random_triangles(rng, n, extent, shape=SHAPE):
    """float32 (n, 3, 2) triangles with bounding boxes of about ``extent`` pixels, anywhere on the image."""
    h, w = shape
    origin = rng.uniform([-2, -2], [w + 2 - extent, h + 2 - extent], size=(n, 1, 2))
    return (origin + rng.uniform(0, extent, size=(n, 3, 2))).astype(np.float32)


rasterize = jax.jit(raster.rasterize, static_argnames=("shape", "window"))
covered = jax.jit(raster.covered, static_argnames=("shape", "window"))


def test_window_for_is_floor_plus_one():
    assert raster.window_for(0.0) == 1
    assert raster.window_for(2.99) == 3
    assert raster.window_for(3.0) == 4
    with pytest.raises(ValueError):
        raster.window_for(-1.0)


@pytest.mark.parametrize(("extent", "count"), [(0.7, 1500), (2.5, 150), (6.0, 40)])
def test_coverage_is_exact_for_either_winding(extent, count):
    rng = np.random.default_rng(int(extent * 10))
    xy = random_triangles(rng, count, extent)
    window = raster.window_for(extent)
    inside, clear = brute_force(xy, SHAPE)
    each = jax.jit(jax.vmap(lambda t: raster.covered(t[None], SHAPE, window)))  # every triangle on its own
    for tris in (xy, xy[:, ::-1]):  # counter-clockwise and clockwise
        np.testing.assert_array_equal(np.asarray(each(tris))[clear], inside[clear])
        got = np.asarray(rasterize(tris, jnp.zeros(tris.shape[:2]), shape=SHAPE, window=window).tri_id) >= 0
        union = clear.all(0)
        np.testing.assert_array_equal(got[union], inside.any(0)[union])
    assert inside[clear].sum() > 30  # the test drew something


@pytest.mark.parametrize(("spacing", "origin", "cell"), [(0.02, -0.0775, 0.004), (0.03, -0.1115, 0.006)])
def test_a_mesh_has_no_cracks(spacing, origin, cell):
    # A flat 8 x 8 grid mesh mapped to pixels in float32 as the coverage metric does: its cell diagonals run
    # through pixel centres up to rounding. Every pixel centre inside the mesh is covered, in either winding.
    g = np.arange(8, dtype=np.float32) * np.float32(spacing) - np.float32(3.5 * spacing)
    gy, gx = np.meshgrid(g, g, indexing="ij")
    v = (jnp.stack([gx, gy], -1).reshape(-1, 2) - jnp.float32(origin)) / jnp.float32(cell)
    i, j = np.meshgrid(np.arange(7), np.arange(7), indexing="ij")
    a = (i * 8 + j).ravel()
    tris = np.concatenate([np.stack([a, a + 1, a + 9], -1), np.stack([a, a + 9, a + 8], -1)])
    xy = np.asarray(v)[tris]
    size = int(np.ceil(xy.max()))
    window = raster.window_for(float((xy.max(1) - xy.min(1)).max()))
    lo, hi = xy.reshape(-1, 2).min(0) + 1e-3, xy.reshape(-1, 2).max(0) - 1e-3
    r, c = np.meshgrid(np.arange(size) + 0.5, np.arange(size) + 0.5, indexing="ij")
    interior = (c > lo[0]) & (c < hi[0]) & (r > lo[1]) & (r < hi[1])
    for t in (xy, xy[:, ::-1]):
        for got in (covered(t, shape=(size, size), window=window),
                    rasterize(t, np.zeros(t.shape[:2]), shape=(size, size), window=window).tri_id >= 0,
                    raster.covered(t, (size, size), window)):  # the last one eager
            got = np.asarray(got)
            assert got[interior].all()
            assert not got[~interior & ((c < lo[0] - 2e-3) | (c > hi[0] + 2e-3))].any()


def test_pixels_beyond_the_window_are_missed():
    tri = np.array([[[2.2, 1.3], [14.6, 3.0], [5.0, 12.8]]], np.float32)  # extent 12.4 x 11.5 pixels
    inside, _ = brute_force(tri, SHAPE)
    small = np.asarray(covered(tri, shape=SHAPE, window=4))
    full = np.asarray(covered(tri, shape=SHAPE, window=raster.window_for(12.4)))
    np.testing.assert_array_equal(full, inside[0])
    assert not (small & ~inside[0]).any()  # a small window only loses pixels
    assert small.sum() < inside[0].sum()
    rows, cols = np.nonzero(small)
    assert cols.max() < 3 + 4 and rows.max() < 2 + 4  # all within the window from ceil(min - 0.5)


def test_nearest_triangle_wins_whatever_the_order():
    big = [[1.0, 1.0], [30.0, 2.0], [3.0, 22.0]]
    small = [[8.0, 6.0], [16.0, 6.0], [8.0, 14.0]]
    for near_first in (True, False):
        xy = np.array([small, big] if near_first else [big, small], np.float32)
        z = np.array([[0.2] * 3, [0.7] * 3] if near_first else [[0.7] * 3, [0.2] * 3], np.float32)
        for sign in (1.0, -1.0):  # the far triangle nearer: then it wins over the small one
            ras = rasterize(xy, z * sign, shape=SHAPE, window=30, z_range=(-1.0, 1.0))
            small_id = 0 if near_first else 1
            winner = small_id if sign > 0 else 1 - small_id
            assert int(ras.tri_id[9, 9]) == winner  # inside both
            assert int(ras.tri_id[3, 20]) == 1 - small_id  # only in the big one
            assert int(ras.tri_id[23, 31]) == -1  # in neither


def test_depth_is_interpolated_across_the_triangle():
    # Two triangles over the whole image, crossing in depth: each wins where its plane is nearer.
    xy = np.array([[[-1.0, -1.0], [100.0, -1.0], [-1.0, 100.0]], [[33.0, 25.0], [-70.0, 25.0], [33.0, -80.0]]],
                  np.float32)
    z = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.5]], np.float32)
    ras = rasterize(xy, z, shape=SHAPE, window=106)
    tri, bary = np.asarray(ras.tri_id), np.asarray(ras.bary)
    depth = np.sum(bary * z[np.maximum(tri, 0)], -1)
    # Each triangle's depth plane z = alpha + beta x + gamma y, solved on the host.
    r, c = np.meshgrid(np.arange(SHAPE[0]) + 0.5, np.arange(SHAPE[1]) + 0.5, indexing="ij")
    planes = [np.linalg.solve(np.c_[np.ones(3), xy[t].astype(np.float64)], z[t]) for t in range(2)]
    depth_a, depth_b = (p[0] + p[1] * c + p[2] * r for p in planes)
    inside, _ = brute_force(xy, SHAPE)
    clear = inside[0] & inside[1] & (np.abs(depth_a - depth_b) > 1e-3)
    expect = np.where(depth_a <= depth_b, 0, 1)
    np.testing.assert_array_equal(tri[clear], expect[clear])
    assert set(tri[clear].tolist()) == {0, 1}  # each wins somewhere
    np.testing.assert_allclose(depth[tri >= 0], np.where(tri == 0, depth_a, depth_b)[tri >= 0], atol=1e-5)


def test_equal_depths_go_to_the_lowest_id():
    tri = [[1.0, 1.0], [20.0, 1.0], [1.0, 20.0]]
    xy = np.array([tri, tri, tri], np.float32)
    ras = rasterize(xy, np.full((3, 3), 0.5, np.float32), shape=SHAPE, window=20)
    assert set(np.unique(np.asarray(ras.tri_id)).tolist()) == {-1, 0}


def test_barycentrics_reconstruct_the_pixel_centre():
    rng = np.random.default_rng(3)
    xy = random_triangles(rng, 30, 5.0)
    ras = rasterize(xy, rng.uniform(size=(30, 3)).astype(np.float32), shape=SHAPE, window=6)
    tri, bary = np.asarray(ras.tri_id), np.asarray(ras.bary)
    drawn = tri >= 0
    assert drawn.sum() > 50
    r, c = np.meshgrid(np.arange(SHAPE[0]) + 0.5, np.arange(SHAPE[1]) + 0.5, indexing="ij")
    point = np.einsum("hwk,hwkd->hwd", bary, xy[np.maximum(tri, 0)])
    np.testing.assert_allclose(point[drawn], np.stack([c, r], -1)[drawn], atol=1e-4)
    np.testing.assert_allclose(bary[drawn].sum(-1), 1.0, atol=1e-5)
    assert (bary[drawn] >= -1e-6).all()
    assert (bary[~drawn] == 0).all()


def test_off_image_invalid_and_non_finite_triangles():
    xy = np.array([
        [[-5.0, -5.0], [10.0, -5.0], [-5.0, 10.0]],  # partly on the image: its on-image corner is drawn
        [[1e9, 1e9], [1e9 + 1, 1e9], [1e9, 1e9 + 1]],  # far off: nothing, and no overflow
        [[4.0, 4.0], [12.0, 4.0], [4.0, 12.0]],  # marked invalid
        [[np.nan, 4.0], [12.0, 4.0], [4.0, 12.0]],  # not finite
        [[20.0, 10.0], [20.0, 10.0], [20.0, 10.0]],  # degenerate: covers nothing
    ], np.float32)
    valid = np.array([True, True, False, True, True])
    ras = rasterize(xy, np.zeros((5, 3), np.float32), shape=SHAPE, window=16, valid=valid)
    tri = np.asarray(ras.tri_id)
    assert set(np.unique(tri).tolist()) == {-1, 0}
    assert tri[0, 0] == 0 and tri[1, 1] == 0 and tri[0, 3] == 0 and tri[3, 3] == -1 and tri[6, 6] == -1
    np.testing.assert_array_equal(np.asarray(covered(xy, shape=SHAPE, window=16, valid=valid)), tri >= 0)


def test_batches_match_single_runs():
    rng = np.random.default_rng(7)
    xy = np.stack([random_triangles(rng, 25, 4.0) for _ in range(4)])
    z = rng.uniform(size=(4, 25, 3)).astype(np.float32)
    fn = jax.jit(jax.vmap(functools.partial(raster.rasterize, shape=SHAPE, window=5)))
    batched, one = fn(xy, z), fn(xy[:1], z[:1])
    eager = raster.rasterize(xy[0], z[0], shape=SHAPE, window=5)
    for i in range(4):
        single = rasterize(xy[i], z[i], shape=SHAPE, window=5)
        for got in (batched.tri_id[i],) + ((one.tri_id[0], eager.tri_id) if i == 0 else ()):
            np.testing.assert_array_equal(np.asarray(got), np.asarray(single.tri_id))
        np.testing.assert_array_equal(np.asarray(batched.bary[i]), np.asarray(single.bary))
    assert (np.asarray(batched.tri_id) >= 0).sum() > 100
    cov = jax.jit(jax.vmap(lambda t: raster.covered(t, SHAPE, 5)))(xy)
    np.testing.assert_array_equal(np.asarray(cov), np.asarray(batched.tri_id) >= 0)


def test_too_many_triangles_for_the_key_is_refused():
    assert raster.id_bits(1) == 1 and raster.id_bits(3042) == 12 and raster.id_bits(4096) == 12
    big = jax.ShapeDtypeStruct((1 << 23 + 1, 3, 2), jnp.float32)
    zbig = jax.ShapeDtypeStruct((1 << 23 + 1, 3), jnp.float32)
    with pytest.raises(ValueError, match="bits of depth"):
        jax.eval_shape(functools.partial(raster.rasterize, shape=SHAPE, window=2), big, zbig)
