"""Vertical rays and footprints: what the cup touches, where a held object lands, and the layouts' free space."""

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.raven import geometry, heightmap, layout, poses


@jax.jit
def _pose(yaw):
    """The rotation matrix (3, 3) of a turn by ``yaw`` about +z."""
    q = poses.yaw_quat(yaw)
    return jnp.stack([poses.rotate(q, e) for e in jnp.eye(3)], axis=-1)


def _box(x, y, z, half, yaw=0.0):
    """A box's (pos, mat, size) at (x, y, z) with half extents ``half``, turned ``yaw`` about +z."""
    return jnp.asarray([x, y, z], jnp.float32), _pose(np.float32(yaw)), jnp.asarray(half, jnp.float32)


def _stack(*boxes):
    return tuple(jnp.stack(parts) for parts in zip(*boxes, strict=True))


def test_a_ray_finds_the_top_of_the_highest_box_or_the_table():
    boxes = _stack(_box(0.5, 0.0, 0.02, (0.02, 0.02, 0.02), yaw=np.pi / 4), _box(0.6, 0.0, 0.05, (0.01, 0.01, 0.05)))
    points = np.asarray([[0.5, 0.0], [0.5 + 0.027, 0.0], [0.5 + 0.029, 0.0], [0.6, 0.0], [0.7, 0.0]], np.float32)
    cast_down = jax.jit(geometry.cast_down)
    height, box = cast_down(points, *boxes, np.ones(2, bool))
    # the turned box reaches 2.83 cm along x (its corner), not 2.9
    np.testing.assert_allclose(height, [0.04, 0.04, 0.0, 0.1, 0.0], atol=1e-6)
    assert box.tolist() == [0, 0, -1, 1, -1]
    hidden, _ = cast_down(points, *boxes, np.asarray([False, True]))
    assert float(hidden[0]) == 0.0


def test_a_held_box_lands_on_the_wall_under_it_and_passes_one_beside_it():
    """A 4 cm cube held high comes down onto a 2 mm wall when their footprints overlap and onto the table when
    they miss each other by a millimetre."""
    wall = _box(0.5, 0.0, 0.02, (0.001, 0.05, 0.02))
    land = jax.jit(lambda x: geometry.landing_height(
        _stack(_box(x, 0.0, 0.5, (0.02, 0.02, 0.02)), wall), _stack(wall, wall), jnp.asarray([False, True]),
        jnp.asarray([True, False])))
    on_wall, beside = float(land(0.5 + 0.02)), float(land(0.5 + 0.022))
    assert on_wall == np.float32(0.04 - 0.48)  # bottom 0.48 raised onto the wall top 0.04
    assert beside == np.float32(0.0 - 0.48)  # onto the table


def test_free_space_is_the_erosion_of_what_is_taken():
    rng = np.random.default_rng(0)
    taken = rng.random((24, 18)) < 0.03
    for window in (5, 6):
        free = np.asarray(jax.jit(layout.free_pixels, static_argnums=1)(jnp.asarray(taken), window))
        before, after = window // 2, window - 1 - window // 2
        expected = np.array([[not taken[max(r - before, 0):r + after + 1, max(c - before, 0):c + after + 1].any()
                              for c in range(18)] for r in range(24)])
        np.testing.assert_array_equal(free, expected)


def test_pixels_and_points_convert_both_ways():
    rc = np.asarray([[0.0, 0.0], [319.0, 159.0], [12.25, 100.5]], np.float32)
    xy = np.asarray(jax.jit(heightmap.pixel_to_world)(rc))
    np.testing.assert_allclose(xy[0], [0.25 + 0.0015625, -0.5 + 0.0015625])
    np.testing.assert_allclose(xy[1], [0.75 - 0.0015625, 0.5 - 0.0015625])
    np.testing.assert_allclose(jax.jit(heightmap.world_to_pixel)(xy), rc, atol=1e-4)
    assert (heightmap.ROWS, heightmap.COLS) == (320, 160) and heightmap.PIXEL_SIZE == 0.003125
