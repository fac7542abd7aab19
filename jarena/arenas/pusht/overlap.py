"""Exact coverage of the goal by the T: ``area(T ∩ goal) / area(goal)``, on the device.

Each T is two boxes that do not overlap, so the intersection's area is the sum over the 2 x 2 pairs of a block
box and a goal box of the area of their intersection, a convex polygon. Each pair is clipped in the goal box's
frame (where its four half-planes are axis-aligned) by Sutherland-Hodgman with fixed shapes: clipping against a
half-plane maps every vertex outside onto the boundary line and inserts the crossing point of every edge that
crosses it, so a polygon of n points becomes one of 2n (points doubled or on the line add no area, whatever their
order along it: the closed path's winding number is unchanged inside the half-plane and zero outside it). Four
half-planes take the box's 4 corners to 64 points; the shoelace formula gives the area. Pure and jittable; vmap it
over poses.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jarena.arenas.pusht import geometry


def _next(values: jax.Array) -> jax.Array:
    return jnp.concatenate([values[1:], values[:1]])


def _clip(along: jax.Array, across: jax.Array, bound: jax.Array, upper: bool) -> tuple[jax.Array, jax.Array]:
    """A closed polygon of n points, coordinates ``along`` the clipping axis and ``across`` it ((n,) each),
    clipped to ``along <= bound`` (``upper``) or ``>= bound``: 2n points."""
    d = (along - bound) if upper else (bound - along)  # > 0: outside
    out, out_next = d > 0, _next(d) > 0
    kept = jnp.where(out, bound, along)
    crosses = out != out_next
    t = d / jnp.where(crosses, d - _next(d), 1.0)
    crossing = across + t * (_next(across) - across)
    inserted_along = jnp.where(crosses, bound, kept)
    inserted_across = jnp.where(crosses, crossing, across)
    return (jnp.stack([kept, inserted_along], 1).reshape(-1), jnp.stack([across, inserted_across], 1).reshape(-1))


def _shoelace(x: jax.Array, y: jax.Array) -> jax.Array:
    return 0.5 * jnp.sum(x * _next(y) - y * _next(x))


def _box_intersection(quad: jax.Array, box: jax.Array) -> jax.Array:
    """Area of a convex quadrilateral (4, 2) clipped by an axis-aligned box ``(x_min, x_max, y_min, y_max)``."""
    x, y = quad[:, 0], quad[:, 1]
    x, y = _clip(x, y, box[0], upper=False)
    x, y = _clip(x, y, box[1], upper=True)
    y, x = _clip(y, x, box[2], upper=False)
    y, x = _clip(y, x, box[3], upper=True)
    return jnp.abs(_shoelace(x, y))


def intersection_area(pose: jax.Array, goal: jax.Array) -> jax.Array:
    """float32 (): area of the T at ``pose`` (3,) intersected with the T at ``goal`` (3,), square units."""
    pose, goal = jnp.asarray(pose, jnp.float32), jnp.asarray(goal, jnp.float32)
    # the block's boxes in the goal's body frame: R(goal)^T (R(pose) p + t - t_goal)
    relative = geometry.rotation(goal[2]).T @ geometry.rotation(pose[2])
    shift = geometry.rotation(goal[2]).T @ (pose[:2] - goal[:2])
    quads = jnp.asarray(geometry.box_corners()) @ relative.T + shift  # (2, 4, 2)
    boxes = jnp.asarray(geometry.BOXES)
    pairs = jnp.repeat(quads, 2, axis=0), jnp.tile(boxes, (2, 1))  # (block box, goal box) x 4
    return jnp.sum(jax.vmap(_box_intersection)(*pairs))


def coverage(pose: jax.Array, goal: jax.Array | None = None) -> jax.Array:
    """float32 (): the fraction of the goal T covered by the T at ``pose``, in [0, 1].

    Args:
      pose: float32 (3,), the block's ``(x, y, angle)`` as ``pusht_env`` reports it (the body origin, not the
        centre of gravity; see :mod:`.geometry`).
      goal: float32 (3,), the goal pose; ``pusht_env``'s ``(256, 256, pi/4)`` when ``None``.
    """
    goal = jnp.asarray(geometry.GOAL_POSE if goal is None else goal, jnp.float32)
    return jnp.clip(intersection_area(pose, goal) / geometry.AREA, 0.0, 1.0)
