"""DrQ's random shift: whole-pixel shifts within the pad, borders repeated, one shift per image."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena_agents.augment import random_shift


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
