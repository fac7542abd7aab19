"""SoftGym's top-down camera: projection, colours of the two faces, depth, z-buffering, batching, visibility."""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena.arenas.cloth import camera
from jarena.arenas.cloth.mesh import ClothMesh

MESH = ClothMesh(rows=20, cols=20, spacing=0.02)  # 0.38 m square
RES = 128
PARAMS = camera.CameraParams()
H = 1.5


def grid(mesh=MESH):
    return mesh.rest_positions.reshape(mesh.rows, mesh.cols, 3).astype(np.float64)


def fold(p, k, gap):
    """Rows beyond ``k`` reflected about row ``k`` onto the rest, ``gap`` metres above (below if negative)."""
    p = p.copy()
    p[k + 1:, :, 1] = 2 * p[k, 0, 1] - p[k + 1:, :, 1]
    p[k + 1:, :, 2] += gap
    return p


def flat(p):
    return np.asarray(p, np.float32).reshape(-1, 3)


@functools.cache
def renderer(resolution=RES, window=None):
    return jax.jit(lambda p, params: camera.render(p, MESH, params, resolution, window))


def render(p, params=PARAMS, resolution=RES):
    return {k: np.asarray(v) for k, v in renderer(resolution)(flat(p), params).items()}


def face(rgb, mask, params=PARAMS):
    """int (R, R): 1 where a cloth pixel's colour is a shade of the front colour, -1 of the back, 0 off the
    cloth (by the angle between colour vectors; shading only scales them)."""
    rgb = rgb.astype(np.float64)
    unit = lambda c: np.asarray(c, np.float64) / np.linalg.norm(c)
    cos = lambda c: (rgb @ unit(c)) / np.maximum(np.linalg.norm(rgb, axis=-1), 1e-9)
    front, back = cos(params.front_rgb), cos(params.back_rgb)
    assert (np.maximum(front, back)[mask] > 0.999).all()  # every cloth pixel is one of the two, shaded
    return np.where(mask, np.where(front > back, 1, -1), 0)


def pixel_of(points, params=PARAMS, resolution=RES):
    """int (..., 2) (row, column) of the pixel containing each world point's image."""
    uv = np.asarray(camera.world_to_pixel(np.asarray(points, np.float32), params))
    col_row = np.floor((uv + 1) * resolution / 2).astype(int)
    return col_row[..., ::-1]


def test_pixel_world_round_trip_and_softgym_span():
    rng = np.random.default_rng(0)
    uv = rng.uniform(-1, 1, (100, 2)).astype(np.float32)
    z = rng.uniform(-0.1, 0.6, 100).astype(np.float32)
    xy = camera.pixel_to_world(uv, z, PARAMS)
    back = camera.world_to_pixel(jnp.concatenate([xy, z[:, None]], -1), PARAMS)
    np.testing.assert_allclose(np.asarray(back), uv, atol=1e-5)
    half = math.tan(math.radians(22.5)) * 1.5
    np.testing.assert_allclose(np.asarray(camera.pixel_to_world(jnp.array([[1.0, 1.0], [-1.0, -1.0]]), 0.0, PARAMS)),
                               [[half, -half], [-half, half]], rtol=1e-6)  # v = -1 is the top row: world +y
    assert half == pytest.approx(0.621, abs=0.001)  # SoftGym's +-0.62 m on the floor
    # Image right is world +x, image up is world +y.
    uv = np.asarray(camera.world_to_pixel(jnp.array([[0.3, 0.0, 0.0], [0.0, 0.3, 0.0], [0.0, 0.0, 0.7]]), PARAMS))
    assert uv[0, 0] > 0 and uv[0, 1] == 0 and uv[1, 1] < 0 and uv[1, 0] == 0 and (uv[2] == 0).all()
    # Pixel centres: first and last of a row.
    centres = np.asarray(camera.pixel_uv(4))
    np.testing.assert_allclose(centres[0, 0], [-0.75, -0.75])
    np.testing.assert_allclose(centres[1, 3], [0.75, -0.25])


def test_render_window_formula():
    mesh = ClothMesh.of_size(0.4, 0.4, cols=40)
    t = math.tan(math.radians(22.5))
    extent = 1.5 * math.sqrt(2) * mesh.spacing * math.sqrt(1 + t * t) * 128 / (2 * t * (1.5 - 0.5))
    assert camera.render_window(mesh, 128) == math.floor(extent) + 1 == 4
    assert camera.render_window(mesh, 256) == 8
    assert camera.render_window(mesh, 128, stretch=3.0, max_z=1.0) == 15
    with pytest.raises(ValueError):
        camera.render_window(mesh, 128, max_z=1.5)


def test_flat_cloth_face_up_shows_the_front_over_its_projected_area():
    out = render(grid(), resolution=256)
    mask = out["mask"]
    assert (face(out["rgb"], mask) >= 0).all() and mask.any()
    side = MESH.width * 256 / (2 * H * math.tan(math.radians(22.5)))  # projected side in pixels
    assert mask.sum() == pytest.approx(side**2, rel=0.03)
    # The mask is a centred square.
    rows, cols = np.nonzero(mask)
    assert rows.min() + rows.max() == pytest.approx(255, abs=1) and cols.min() + cols.max() == pytest.approx(255, abs=1)
    # The floor: its colour, depth H.
    floor = np.round(np.asarray(PARAMS.floor_rgb) * 255)
    assert (out["rgb"][~mask] == floor).all() and (out["depth"][~mask] == np.float32(H)).all()


def test_flipped_cloth_shows_the_back():
    p = grid()
    p[..., 0] *= -1  # mirrored: the triangles turn clockwise seen from above, their normals point down
    out = render(p)
    assert out["mask"].sum() > 1000
    assert (face(out["rgb"], out["mask"]) <= 0).all()
    np.testing.assert_array_equal(out["mask"], render(grid())["mask"])  # same silhouette


def test_folded_cloth_shows_both_colours_where_expected():
    p = fold(grid(), 12, 0.02)  # rows 13..19 folded over rows 11..5; rows 0..4 stay uncovered
    out = render(p)
    f = face(out["rgb"], out["mask"])
    top = pixel_of(p[15, 3:17])  # particles of the folded-over layer (seen from its back)
    bottom = pixel_of(p[2, 3:17])  # uncovered front
    assert (f[top[:, 0], top[:, 1]] == -1).all()
    assert (f[bottom[:, 0], bottom[:, 1]] == 1).all()
    # The cloth now spans 12 row spacings from above: 5 of front (rows 0..5), 7 of back (rows 5..12).
    assert (f == -1).sum() / out["mask"].sum() == pytest.approx(7 / 12, abs=0.05)


def test_depth_is_camera_height_minus_z():
    p = grid()
    p[..., 2] = 0.3
    out = render(p)
    mask = out["mask"]
    assert mask.sum() > 1000
    np.testing.assert_allclose(out["depth"][mask], 1.2, atol=1e-3)
    assert (out["depth"][~mask] == np.float32(H)).all()
    assert out["depth"].dtype == np.float32 and out["rgb"].dtype == np.uint8 and out["mask"].dtype == bool
    assert out["rgb"].shape == (RES, RES, 3) and out["depth"].shape == out["mask"].shape == (RES, RES)
    # A sloped cloth: depth follows the surface (perspective-correct interpolation).
    p = grid()
    p[..., 2] = 0.2 + 0.5 * p[..., 1]  # rises towards +y
    out = render(p)
    rows, cols = np.nonzero(out["mask"])
    uv = np.asarray(camera.pixel_uv(RES))[rows, cols]
    d = out["depth"][rows, cols]
    # The surface z = 0.2 + 0.5 y: the pixel's ray at depth d is at y = -v t d, z = H - d.
    y = np.asarray(camera.pixel_to_world(uv, H - d, PARAMS))[:, 1]
    np.testing.assert_allclose(H - d, 0.2 + 0.5 * y, atol=1e-3)


@pytest.mark.parametrize("gap", [0.03, -0.03])
def test_the_higher_layer_wins(gap):
    p = fold(grid(), 9, gap)  # rows 10..19 onto rows 8..-1, above (gap > 0) or below (gap < 0)
    p[..., 2] += 0.1
    out = render(p)
    f = face(out["rgb"], out["mask"])
    both = pixel_of(p[2:7, 3:17].reshape(-1, 3))  # pixels over the middle of the overlap
    seen = f[both[:, 0], both[:, 1]]
    depth = out["depth"][both[:, 0], both[:, 1]]
    if gap > 0:  # the folded layer is on top, its back up
        assert (seen == -1).all()
        np.testing.assert_allclose(depth, H - 0.1 - gap, atol=1e-3)
    else:  # folded under: the front of the lower rows is on top
        assert (seen == 1).all()
        np.testing.assert_allclose(depth, H - 0.1, atol=1e-3)


def test_folds_are_shaded():
    # A cloth tilted 60 degrees about the x axis is darker by the cosine: ambient + (1 - ambient) cos.
    p = grid()
    y = p[..., 1].copy()
    p[..., 1], p[..., 2] = y * 0.5, 0.2 + y * math.sqrt(3) / 2
    out = render(p)
    mask = out["mask"]
    centre = out["rgb"][RES // 2, RES // 2].astype(np.float64)
    flat_centre = render(grid())["rgb"][RES // 2, RES // 2].astype(np.float64)
    ambient = float(PARAMS.ambient)
    assert mask[RES // 2, RES // 2]
    np.testing.assert_allclose(centre / flat_centre, ambient + (1 - ambient) * 0.5, atol=0.03)


def test_jit_matches_eager_and_vmap_matches_single_runs():
    ps = np.stack([flat(grid()), flat(grid()), flat(fold(grid(), 9, -0.02))])
    ps[2, :, :2] += 0.1
    params = jax.tree.map(lambda *x: jnp.stack(x), PARAMS, PARAMS.replace(height=jnp.float32(1.3)),
                          PARAMS.replace(front_rgb=jnp.array([0.9, 0.2, 0.2], jnp.float32), fov=jnp.float32(50.0)))
    fn = jax.vmap(lambda p, c: camera.render(p, MESH, c, 64, 5))
    batched, one = jax.jit(fn)(ps, params), jax.jit(fn)(ps[:1], jax.tree.map(lambda x: x[:1], params))
    single = jax.jit(lambda p, c: camera.render(p, MESH, c, 64, 5))
    for i in range(3):
        jitted = single(ps[i], jax.tree.map(lambda x, i=i: x[i], params))
        for k in ("rgb", "depth", "mask"):
            np.testing.assert_array_equal(np.asarray(jitted[k]), np.asarray(batched[k][i]))
            if i == 0:
                np.testing.assert_array_equal(np.asarray(jitted[k]), np.asarray(one[k][0]))
    # Eager runs op by op; XLA's fused code may round the last bit differently.
    eager, jitted = camera.render(ps[2], MESH, PARAMS, 64, 5), single(ps[2], PARAMS)
    assert eager["mask"].sum() > 150
    np.testing.assert_array_equal(np.asarray(eager["mask"]), np.asarray(jitted["mask"]))
    np.testing.assert_allclose(np.asarray(eager["depth"]), np.asarray(jitted["depth"]), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(eager["rgb"]), np.asarray(jitted["rgb"]), atol=1)
    # The camera 1.3 m up instead of 1.5 m: the cloth looks bigger by the ratio of the heights.
    ratio = batched["mask"][1].sum() / batched["mask"][0].sum()
    assert ratio == pytest.approx((1.5 / 1.3) ** 2, rel=0.1)
    red = np.asarray(batched["rgb"][2, 32, 32])  # the third cloth's front, coloured by its own params
    assert red[0] > 200 and red[1] < 60 and red[2] < 60


def test_particles_project_into_the_mask():
    rng = np.random.default_rng(2)
    p = grid()
    p[..., 2] = 0.05 + 0.03 * np.sin(7 * p[..., 0] + 1) * np.cos(5 * p[..., 1]) + 0.002 * rng.normal(size=p.shape[:2])
    p[..., :2] += 0.004 * rng.normal(size=p.shape[:2] + (2,))
    out = render(p)
    inner = pixel_of(p[1:-1, 1:-1].reshape(-1, 3))  # interior particles (a corner's pixel centre may be off it)
    assert out["mask"][inner[:, 0], inner[:, 1]].all()
    assert out["mask"].sum() > 1000


def test_visibility_of_corners():
    vis = lambda p, **kw: np.asarray(camera.visible(flat(p), MESH, MESH.corners, PARAMS, RES, **kw))
    assert vis(grid()).all()
    # Fold rows 8..19 over rows 6..-5: the folded layer overhangs the lower corners (row 0) and hides them;
    # its own corners (row 19) are on top.
    p = fold(grid(), 7, 0.02)
    np.testing.assert_array_equal(vis(p), [False, False, True, True])  # corners (0, 0), (0, c), (r, c), (r, 0)
    # A layer closer than the tolerance does not hide.
    np.testing.assert_array_equal(vis(fold(grid(), 7, 0.005)), [True, True, True, True])
    np.testing.assert_array_equal(vis(fold(grid(), 7, 0.005), tol=0.002), [False, False, True, True])
    # Rows 13..19 folded under rows 11..5: the folded corners are hidden beneath, the others on top.
    np.testing.assert_array_equal(vis(fold(grid(), 12, -0.02)), [True, True, False, False])
    # Out of the image.
    p = grid()
    p[..., 0] += 0.5
    np.testing.assert_array_equal(vis(p), [True, False, False, True])
    # Batched and jitted.
    ps = np.stack([flat(grid()), flat(fold(grid(), 7, 0.02))])
    got = jax.jit(jax.vmap(lambda q: camera.visible(q, MESH, MESH.corners, PARAMS)))(ps)
    np.testing.assert_array_equal(np.asarray(got), [[True] * 4, [False, False, True, True]])
    assert np.asarray(camera.visible(flat(grid()), MESH, jnp.arange(MESH.num_particles), PARAMS)).all()
