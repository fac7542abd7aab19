"""DrQ's random shift (whole-pixel shifts within the pad, borders repeated, one shift per image) and the
quarter turns of images with their image points."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena_agents.augment import random_rotate90, random_shift, rotate_points


def test_each_image_is_a_shifted_copy_with_repeated_borders():
    rng = np.random.default_rng(0)
    images = jnp.asarray(rng.integers(0, 256, (2, 5, 12, 10, 3)), jnp.uint8)
    out = np.asarray(jax.jit(random_shift, static_argnums=2)(jax.random.key(1), images, 2))
    assert out.shape == images.shape and out.dtype == np.uint8
    shifts = set()
    for index in np.ndindex(2, 5):
        padded = np.pad(np.asarray(images[index]), ((2, 2), (2, 2), (0, 0)), mode="edge")
        found = [(dy, dx) for dy in range(5) for dx in range(5)
                 if np.array_equal(padded[dy:dy + 12, dx:dx + 10], out[index])]
        assert found, f"image {index} is not a shift of its input"
        shifts.add(found[0])
    assert len(shifts) > 3  # images draw their own shifts
    np.testing.assert_array_equal(random_shift(jax.random.key(1), images, 2), out)  # same key, same shifts
    np.testing.assert_array_equal(random_shift(jax.random.key(1), images, 0), images)


def test_bad_arguments():
    with pytest.raises(ValueError, match="pad must be a non-negative integer, got -1"):
        random_shift(jax.random.key(0), jnp.zeros((4, 4, 3)), -1)
    with pytest.raises(ValueError, match=r"needs images of shape \(..., H, W, C\), got shape \(4, 4\)"):
        random_shift(jax.random.key(0), jnp.zeros((4, 4)), 2)


def test_rotate_points_follows_numpy_rot90():
    """A lit pixel's centre, as a normalised image point, moves as np.rot90 moves the pixel."""
    size, row, col = 8, 1, 6
    image = np.zeros((size, size), np.uint8)
    image[row, col] = 1
    centre = lambda r, c: [(c + 0.5) / (size / 2) - 1, (r + 0.5) / (size / 2) - 1]  # noqa: E731  (u, v)
    for turns in range(5):
        r, c = np.argwhere(np.rot90(image, turns))[0]
        np.testing.assert_allclose(rotate_points(jnp.asarray(centre(row, col)), turns), centre(r, c), atol=1e-6)


def test_random_rotate90_turns_each_sample_and_its_points_alike():
    images = jax.random.randint(jax.random.key(0), (16, 6, 6, 3), 0, 255).astype(jnp.uint8)
    points = jax.random.uniform(jax.random.key(1), (16, 2, 2), minval=-1, maxval=1)
    turned, moved = random_rotate90(jax.random.key(2), {"rgb": images}, points)
    seen = set()
    for i in range(16):
        turns = [k for k in range(4) if np.array_equal(np.rot90(images[i], k), turned["rgb"][i])]
        assert len(turns) == 1
        seen.add(turns[0])
        for _ in range(turns[0]):  # one quarter turn: (u, v) -> (v, -u)
            points = points.at[i].set(jnp.stack([points[i, :, 1], -points[i, :, 0]], -1))
        np.testing.assert_allclose(moved[i], points[i], atol=1e-6)
    assert seen == {0, 1, 2, 3}
    with pytest.raises(ValueError, match="square"):
        random_rotate90(jax.random.key(0), {"rgb": images[:, :, :5]}, points)


def test_a_quarter_turn_of_the_cloth_camera_image_is_the_image_of_the_turned_cloth():
    """Why rotate90 fits the cloth arenas: turning the particles a quarter turn about the camera's axis
    gives exactly the rgb image turned by np.rot90 (and a pixel pick-and-place point turns with it)."""
    arena = jarena.build_arena("cloth|particles:12,resolution:32,depth:false,mask:false")
    state, _ = jax.jit(arena.reset)(jax.random.key(3))
    positions = state.physics.positions
    turned = positions.at[:, 0].set(-positions[:, 1]).at[:, 1].set(positions[:, 0])  # (x, y) -> (-y, x)
    observe = jax.jit(lambda physics: arena.sensor.observe(physics, arena.default_params().sensor)["rgb"])
    image = np.asarray(observe(state.physics))
    assert not np.array_equal(np.rot90(image), image)  # the crumpled cloth has no such symmetry itself
    np.testing.assert_array_equal(np.asarray(observe(state.physics.replace(positions=turned))), np.rot90(image))
