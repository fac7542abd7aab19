"""Image augmentation for agents that learn from pixels.

``random_shift`` is DrQ's augmentation (Kostrikov et al., 2020; Yarats et al., 2021): pad each image by ``pad``
pixels, repeating its border, and crop it back to its size at a random offset, so each image moves by up to
``pad`` pixels in each direction. Pure and jittable; each image of a batch draws its own shift from ``key``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def random_shift(key: jax.Array, images: jax.Array, pad: int = 4) -> jax.Array:
    """Images shifted by random whole pixels, borders repeated.

    Args:
      key: PRNG key.
      images: (..., H, W, C) images of any dtype; every leading index is one image.
      pad: the largest shift in pixels (DrQ's default: 4 for 84 x 84 images).
    Returns:
      An array of the shape and dtype of ``images``; image ``i`` is ``images[i]`` moved by ``(dy, dx)`` drawn
      uniformly from ``{-pad, ..., pad}^2``.
    """
    if not isinstance(pad, int) or isinstance(pad, bool) or pad < 0:
        raise ValueError(f"pad must be a non-negative integer, got {pad!r}")
    if images.ndim < 3:
        raise ValueError(f"random_shift needs images of shape (..., H, W, C), got shape {images.shape}")
    if pad == 0:
        return images
    *batch, h, w, c = images.shape
    flat = images.reshape((-1, h, w, c))
    padded = jnp.pad(flat, ((0, 0), (pad, pad), (pad, pad), (0, 0)), mode="edge")
    offsets = jax.random.randint(key, (flat.shape[0], 2), 0, 2 * pad + 1)

    def crop(image, offset):
        return jax.lax.dynamic_slice(image, (offset[0], offset[1], 0), (h, w, c))

    return jax.vmap(crop)(padded, offsets).reshape(images.shape)
