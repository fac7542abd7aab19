"""Seeded layouts: Ravens' ``get_random_pose``, placing objects one by one in the workspace's free space.

An object of extent ``(x, y, z)`` goes to a pixel drawn uniformly among those whose ``k x k`` square (``k`` the
extent's diagonal in pixels, 45 for a 10 cm object) holds no pixel of an object placed before it nor the image's
border, with a heading drawn uniformly in [0, 2 pi), its origin ``z / 2`` above the table. Everything is in JAX
on the heightmap's grid (:mod:`.heightmap`), so a layout is a pure function of its key.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.raven import geometry, heightmap, poses
from jarena.arenas.raven.scene import Shape


def border() -> jax.Array:
    """bool (ROWS, COLS): the heightmap's outermost pixels, which Ravens counts as taken."""
    mask = np.zeros((heightmap.ROWS, heightmap.COLS), bool)
    mask[0, :] = mask[-1, :] = mask[:, 0] = mask[:, -1] = True
    return jnp.asarray(mask)


def window_pixels(shape: Shape) -> int:
    """The side of the square kept free around an object's pixel: its extent's diagonal in pixels (rounded)."""
    return int(np.round(np.hypot(shape.extent[0], shape.extent[1]) / heightmap.PIXEL_SIZE))


def free_pixels(taken: jax.Array, window: int) -> jax.Array:
    """bool (ROWS, COLS): pixels whose ``window x window`` square (centred as OpenCV's erosion centres it) holds no
    ``taken`` pixel; squares reaching past the image count only the pixels inside."""
    before = window // 2
    after = window - 1 - before
    taken = jax.lax.optimization_barrier(taken.astype(jnp.int32))  # a constant (the border alone) is not folded
    counts = jnp.pad(jnp.cumsum(jnp.cumsum(taken, 0), 1), ((1, 0), (1, 0)))
    rows, cols = taken.shape
    r, c = jnp.arange(rows), jnp.arange(cols)
    r0, r1 = jnp.clip(r - before, 0, rows), jnp.clip(r + after + 1, 0, rows)
    c0, c1 = jnp.clip(c - before, 0, cols), jnp.clip(c + after + 1, 0, cols)
    inside = (counts[r1][:, c1] - counts[r0][:, c1] - counts[r1][:, c0] + counts[r0][:, c0])
    return inside == 0


def footprint(shape: Shape, pos: jax.Array, quat: jax.Array) -> jax.Array:
    """bool (ROWS, COLS): the pixels an object of ``shape`` at ``pos``, ``quat`` covers, seen from above."""
    centres = jnp.asarray([b.pos for b in shape.boxes], jnp.float32)
    half = jnp.asarray([b.size for b in shape.boxes], jnp.float32) / 2
    box_pos = pos + poses.rotate(quat, centres)
    mat = jnp.stack([poses.rotate(quat, e) for e in jnp.eye(3)], axis=-1)
    mats = jnp.broadcast_to(mat, (len(shape.boxes), 3, 3))
    xy = jnp.asarray(heightmap.pixel_centres().reshape(-1, 2))
    return geometry.inside_boxes(xy, box_pos, mats, half).reshape(heightmap.ROWS, heightmap.COLS)


def random_pose(key: jax.Array, taken: jax.Array, shape: Shape) -> tuple[jax.Array, jax.Array, jax.Array]:
    """A pose for ``shape`` in the free space left by ``taken`` (ROWS, COLS): ``(pos (3,), quat (4,), found)``,
    ``found`` false where no pixel is free (the pose is then meaningless)."""
    key_pixel, key_yaw = jax.random.split(key)
    free = free_pixels(taken, window_pixels(shape)).reshape(-1)
    index = jax.random.categorical(key_pixel, jnp.where(free, 0.0, -jnp.inf))
    rc = jnp.stack([index // heightmap.COLS, index % heightmap.COLS]).astype(jnp.float32)
    xy = heightmap.pixel_to_world(rc)
    yaw = jax.random.uniform(key_yaw, (), jnp.float32, 0.0, 2 * np.pi)
    pos = jnp.concatenate([xy, jnp.full((1,), shape.extent[2] / 2, jnp.float32)])
    return pos, poses.yaw_quat(yaw), jnp.any(free)


def place_in_turn(key: jax.Array, shapes: tuple[Shape, ...], taken: jax.Array | None = None
                  ) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """Poses for ``shapes``, placed in order, each in the free space the ones before it left.

    Returns ``(pos (K, 3), quat (K, 4), found (K,), taken)``, ``taken`` the pixels covered at the end.
    """
    taken = border() if taken is None else taken
    out = []
    for i, shape in enumerate(shapes):
        pos, quat, found = random_pose(jax.random.fold_in(key, i), taken, shape)
        taken = taken | (footprint(shape, pos, quat) & found)
        out.append((pos, quat, found))
    pos, quat, found = (jnp.stack(x) for x in zip(*out, strict=True))
    return pos, quat, found, taken
