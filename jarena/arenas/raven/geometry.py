"""Where things touch, seen from above: vertical rays and box footprints.

The suction cup finds what it touches by casting a ray straight down (the suction tip is a 1 mm cylinder in
Ravens), the heightmap is the same ray cast at every pixel, and a held object is lowered until one of its boxes
meets the top of a box under it. All exact for boxes that stand upright (every box of the family at rest);
for a tilted box the footprint test below is conservative (it may stop a held object a little early).

Boxes are given by their centres ``pos`` (..., 3), rotation matrices ``mat`` (..., 3, 3) (columns: the box's axes
in the world) and half extents ``size`` (..., 3), as MuJoCo's ``geom_xpos``, ``geom_xmat`` and ``geom_size``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jarena.arenas.mjx import raycast

SKY = 2.0
"""Height the vertical rays start from, metres (above any object of the family)."""
OVERLAP = 5e-4
"""Footprints must overlap by more than this, metres, for a held box to land on another (a box lowered beside
another, grazing it, passes it)."""


def cast_down(xy: jax.Array, pos: jax.Array, mat: jax.Array, size: jax.Array, visible: jax.Array
              ) -> tuple[jax.Array, jax.Array]:
    """The highest surface straight below points ``xy`` (P, 2): the table (``z = 0``) or a box.

    Args:
      xy: float32 (P, 2) points, metres.
      pos, mat, size: the boxes, (G, 3), (G, 3, 3), (G, 3).
      visible: bool (G,): the boxes the rays see.

    Returns:
      ``(height, box)``: float32 (P,) height of the surface hit, metres, and int32 (P,) the box hit, -1 for the
      table.
    """
    origin = jnp.concatenate([xy, jnp.full(xy.shape[:-1] + (1,), SKY, xy.dtype)], -1)  # (P, 3)
    # into each box's frame: R^T (o - p); the direction (0, 0, -1) becomes minus the third row of R
    local = jnp.einsum("gji,pgj->pgi", mat, origin[:, None, :] - pos[None])
    direction = jnp.broadcast_to(-mat[:, 2, :], local.shape)
    t = raycast.box(local, direction, jnp.broadcast_to(size, local.shape))  # (P, G), inf where missed
    t = jnp.where(visible[None], t, jnp.inf)
    nearest = jnp.argmin(t, axis=-1).astype(jnp.int32)
    t_min = jnp.min(t, axis=-1)
    hit = jnp.isfinite(t_min) & (t_min < SKY)
    return jnp.where(hit, SKY - t_min, 0.0), jnp.where(hit, nearest, -1)


def corners(pos: jax.Array, mat: jax.Array, size: jax.Array) -> jax.Array:
    """float32 (..., 8, 3): the corners of boxes."""
    signs = jnp.asarray([[sx, sy, sz] for sx in (-1.0, 1.0) for sy in (-1.0, 1.0) for sz in (-1.0, 1.0)],
                        pos.dtype)
    return pos[..., None, :] + jnp.einsum("...ij,...kj->...ki", mat, signs * size[..., None, :])


def _planar_axes(mat: jax.Array) -> jax.Array:
    """float32 (..., 2, 2): a box's x and y axes projected onto the table and normalised."""
    axes = jnp.swapaxes(mat[..., :2, :2], -1, -2)  # rows: the x and y axes' (x, y) components
    return axes / jnp.maximum(jnp.linalg.norm(axes, axis=-1, keepdims=True), 1e-9)


def footprints_overlap(corners_a: jax.Array, axes_a: jax.Array, corners_b: jax.Array, axes_b: jax.Array
                       ) -> jax.Array:
    """bool: whether two boxes' shadows on the table overlap by more than :data:`OVERLAP` (separating axes).

    Args:
      corners_a, corners_b: (8, 3) corners; axes_a, axes_b: (2, 2) planar axes (:func:`_planar_axes`).
    """
    axes = jnp.concatenate([axes_a, axes_b], axis=0)  # (4, 2)
    pa, pb = corners_a[:, :2] @ axes.T, corners_b[:, :2] @ axes.T  # (8, 4)
    gap = jnp.maximum(jnp.min(pb, 0) - jnp.max(pa, 0), jnp.min(pa, 0) - jnp.max(pb, 0))
    return jnp.all(gap < -OVERLAP)


def landing_height(held: tuple[jax.Array, jax.Array, jax.Array], others: tuple[jax.Array, jax.Array, jax.Array],
                   solid: jax.Array, held_box: jax.Array) -> jax.Array:
    """How high a held object stops when lowered from above: the offset, metres, to add to its boxes' heights.

    Args:
      held: the held object's boxes as lowered (``pos`` (H, 3) at any height, ``mat``, ``size``), all boxes of
        the scene (H = G), of which ``held_box`` (bool (G,)) are the held object's.
      others: every box of the scene where it is (``pos`` (G, 3), ``mat``, ``size``).
      solid: bool (G,): the boxes that can stop the held object (not its own, not parked away).

    Returns:
      float32 (): ``dz`` such that the held boxes raised by ``dz`` rest on the highest box under them that their
      footprints overlap, or on the table.
    """
    held_corners = corners(*held)  # (G, 8, 3)
    other_corners = corners(*others)
    held_axes, other_axes = _planar_axes(held[1]), _planar_axes(others[1])
    bottom = jnp.min(held_corners[..., 2], axis=-1)  # (G,)
    top = jnp.max(other_corners[..., 2], axis=-1)
    overlap = jax.vmap(lambda ca, aa: jax.vmap(lambda cb, ab: footprints_overlap(ca, aa, cb, ab))(
        other_corners, other_axes))(held_corners, held_axes)  # (G held, G other)
    pairs = overlap & held_box[:, None] & solid[None, :]
    lift = jnp.where(pairs, top[None, :] - bottom[:, None], -jnp.inf)  # raise held box h onto box o
    on_table = jnp.where(held_box, -bottom, -jnp.inf)
    return jnp.maximum(jnp.max(lift), jnp.max(on_table))


def inside_boxes(xy: jax.Array, pos: jax.Array, mat: jax.Array, size: jax.Array) -> jax.Array:
    """bool (P,): which points ``xy`` (P, 2) lie in the shadow of any of the boxes (G, ...) on the table (the boxes
    upright)."""
    axes = _planar_axes(mat)  # (G, 2, 2)
    local = jnp.einsum("gij,pgj->pgi", axes, xy[:, None, :] - pos[None, :, :2])  # (P, G, 2)
    return jnp.any(jnp.all(jnp.abs(local) <= size[None, :, :2], axis=-1), axis=-1)
