"""Image augmentation for agents that learn from pixels.

``random_shift`` is DrQ's augmentation (Kostrikov et al., 2020; Yarats et al., 2021): pad each image by ``pad``
pixels, repeating its border, and crop it back to its size at a random offset, so each image moves by up to
``pad`` pixels in each direction. Pure and jittable; each image of a batch draws its own shift from ``key``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.arena import ArenaSpec
from jarena.core.spec import Box
from jarena_agents import networks
from jarena_agents.config import ConfigError


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


def rotate_points(points: jax.Array, turns: jax.Array) -> jax.Array:
    """Normalised image points (..., 2) as ``(u, v)`` (u: left to right, v: top to bottom, both in [-1, 1]),
    moved with their image turned by ``turns`` quarter turns as :func:`numpy.rot90` turns it (anticlockwise
    on screen): one turn maps ``(u, v)`` to ``(v, -u)``. ``turns``: int, broadcast against ``points[..., 0]``."""
    u, v = points[..., 0], points[..., 1]
    turns = jnp.mod(turns, 4)
    new_u = jnp.select([turns == 0, turns == 1, turns == 2], [u, v, -u], -v)
    new_v = jnp.select([turns == 0, turns == 1, turns == 2], [v, -u, -v], u)
    return jnp.stack([new_u, new_v], axis=-1)


def random_rotate90(key: jax.Array, images: dict, points: jax.Array) -> tuple[dict, jax.Array]:
    """Square images and the image points that go with them (e.g. a pixel pick-and-place action), each
    sample turned by its own random number of quarter turns (0 to 3), as transporter networks augment
    their data: a top-down view of a scene with no preferred direction looks as plausible turned.

    Args:
      key: PRNG key.
      images: dict of (S, H, H, C) images (every key turned alike).
      points: (S, ..., 2) normalised image points ``(u, v)`` (:func:`rotate_points`).
    Returns:
      ``(images, points)`` turned, shapes and dtypes unchanged.
    """
    size = points.shape[0]
    turns = jax.random.randint(key, (size,), 0, 4)

    def turn(image):
        if image.shape[-3] != image.shape[-2]:
            raise ValueError(f"random_rotate90 needs square images, got shape {image.shape}")
        options = jnp.stack([jnp.rot90(image, k, axes=(-3, -2)) for k in range(4)])  # (4, S, H, H, C)
        return jnp.take_along_axis(options, turns[None, :, None, None, None], axis=0)[0]

    points = rotate_points(points, turns.reshape((size,) + (1,) * (points.ndim - 2)))
    return {k: turn(v) for k, v in images.items()}, points


def check_rotate90(spec: ArenaSpec, agent: str) -> None:
    """Raises a ``ConfigError`` naming ``agent`` unless ``augment: rotate90`` can turn this arena's samples: square
    image observations and nothing else, and Box actions in [-1, 1] with an even number of values (image points)."""
    images = networks.image_keys(spec)
    action = spec.action
    problems = []
    if not images:
        problems.append("the arena has no image observations")
    elif any(spec.observation[k].shape[0] != spec.observation[k].shape[1] for k in images):
        problems.append("its images are not square")
    if networks.vector_size(spec, images):
        problems.append("it observes more than images (a vector would not turn with them)")
    if not (isinstance(action, Box) and action.shape and action.shape[-1] % 2 == 0
            and np.all(np.asarray(action.low) == -1.0) and np.all(np.asarray(action.high) == 1.0)):
        problems.append(f"its actions {action!r} are not image points (an even number of values in [-1, 1])")
    if problems:
        raise ConfigError(f"{agent}: augment 'rotate90' does not fit this arena: " + "; ".join(problems))
