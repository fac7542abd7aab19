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


def window_pixels(extent) -> jax.Array:
    """int32 (): the side of the square kept free around an object's pixel: the diagonal of its ``extent`` (x, y,
    z) metres, in pixels (rounded)."""
    extent = jnp.asarray(extent, jnp.float32)
    return jnp.round(jnp.hypot(extent[0], extent[1]) / heightmap.PIXEL_SIZE).astype(jnp.int32)


def free_pixels(taken: jax.Array, window) -> jax.Array:
    """bool (ROWS, COLS): pixels whose ``window x window`` square (centred as OpenCV's erosion centres it) holds no
    ``taken`` pixel; squares reaching past the image count only the pixels inside. ``window`` may be traced."""
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


def shape_boxes(shape: Shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A shape's boxes: centres (B, 3), half extents (B, 3) and headings (B,), in its frame."""
    return (np.asarray([b.pos for b in shape.boxes], np.float32),
            np.asarray([b.size for b in shape.boxes], np.float32) / 2,
            np.asarray([b.yaw for b in shape.boxes], np.float32))


def footprint(boxes: tuple, pos: jax.Array, quat: jax.Array) -> jax.Array:
    """bool (ROWS, COLS): the pixels an object of ``boxes`` (:func:`shape_boxes`, or the episode's) at ``pos``,
    ``quat`` covers, seen from above."""
    centres, half, yaw = (jnp.asarray(x, jnp.float32) for x in boxes)
    box_pos = pos + poses.rotate(quat, centres)
    box_quat = poses.quat_mul(jnp.broadcast_to(quat, yaw.shape + (4,)), poses.yaw_quat(yaw))
    mats = jax.vmap(lambda q: jnp.stack([poses.rotate(q, e) for e in jnp.eye(3)], axis=-1))(box_quat)
    xy = jnp.asarray(heightmap.pixel_centres().reshape(-1, 2))
    return geometry.inside_boxes(xy, box_pos, mats, half).reshape(heightmap.ROWS, heightmap.COLS)


def random_pose(key: jax.Array, taken: jax.Array, extent) -> tuple[jax.Array, jax.Array, jax.Array]:
    """A pose for an object of ``extent`` (x, y, z) metres (may be traced) in the free space left by ``taken``
    (ROWS, COLS): ``(pos (3,), quat (4,), found)``, ``found`` false where no pixel is free (the pose is then
    meaningless)."""
    extent = jnp.asarray(extent, jnp.float32)
    key_pixel, key_yaw = jax.random.split(key)
    free = free_pixels(taken, window_pixels(extent)).reshape(-1)
    index = jax.random.categorical(key_pixel, jnp.where(free, 0.0, -jnp.inf))
    rc = jnp.stack([index // heightmap.COLS, index % heightmap.COLS]).astype(jnp.float32)
    xy = heightmap.pixel_to_world(rc)
    yaw = jax.random.uniform(key_yaw, (), jnp.float32, 0.0, 2 * np.pi)
    pos = jnp.concatenate([xy, extent[2:3] / 2])
    return pos, poses.yaw_quat(yaw), jnp.any(free)


def place_in_turn(key: jax.Array, shapes: tuple[Shape, ...], taken: jax.Array | None = None,
                  present: jax.Array | None = None) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """Poses for ``shapes``, placed in order, each in the free space the ones before it left (one loop over the
    shapes, their boxes padded to the same count with boxes that cover nothing).

    ``present`` (bool (K,), default all): the shapes placed this episode; the others take no space and are not
    found. Returns ``(pos (K, 3), quat (K, 4), found (K,), taken)``, ``taken`` the pixels covered at the end.
    """
    taken = border() if taken is None else taken
    present = jnp.ones(len(shapes), bool) if present is None else jnp.asarray(present, bool)
    count = max(len(shape.boxes) for shape in shapes)

    def padded(shape):
        centres, half, yaw = shape_boxes(shape)
        missing = count - len(shape.boxes)
        return (np.concatenate([centres, np.zeros((missing, 3), np.float32)]),
                np.concatenate([half, -np.ones((missing, 3), np.float32)]),  # a negative size holds no point
                np.concatenate([yaw, np.zeros(missing, np.float32)]))

    boxes = tuple(jnp.asarray(np.stack(parts)) for parts in zip(*(padded(s) for s in shapes), strict=True))
    extents = jnp.asarray([shape.extent for shape in shapes], jnp.float32)

    def place(taken, shape):
        index, extent, centres, half, yaw, here = shape
        pos, quat, found = random_pose(jax.random.fold_in(key, index), taken, extent)
        found = found & here
        return taken | (footprint((centres, half, yaw), pos, quat) & found), (pos, quat, found)

    taken, (pos, quat, found) = jax.lax.scan(place, taken, (jnp.arange(len(shapes)), extents, *boxes, present))
    return pos, quat, found, taken
