"""The top-down image of the PushT scene, rasterised in JAX (batched with the physics under ``jit`` and ``vmap``).

It draws what ``pusht_env`` draws on its 512 x 512 canvas before shrinking it to 96 x 96: a white plane, the goal
T in light green, the T block in light slate grey with a darker 2-unit outline on both sides of each box's edges,
the pusher as a royal-blue disc (radius 15) with a lighter core (radius 11), and the walls as light grey bands 4
units wide. Columns are x and rows are y (down), as in the reference's window. Each pixel averages ``samples`` x
``samples`` points spread over its footprint (the reference's bilinear shrink also blends neighbours at edges).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.pusht import geometry

WHITE = (255, 255, 255)
GOAL = (144, 238, 144)  # LightGreen
BLOCK = (142, 163, 183)  # LightSlateGray lightened by 1.2, the reference's fill
OUTLINE = (119, 136, 153)  # LightSlateGray
PUSHER = (65, 105, 225)  # RoyalBlue
PUSHER_CORE = (78, 126, 255)  # RoyalBlue lightened by 1.2
WALL = (211, 211, 211)  # LightGray
OUTLINE_WIDTH = 2.0
CORE_RADIUS = 11.0
WALL_LINE, WALL_RADIUS = (5.0, 506.0), 2.0


def _box_distances(points: jax.Array, pose: jax.Array) -> jax.Array:
    """Signed distances (..., 2) of plane points (..., 2) to the T's two boxes at ``pose`` (< 0 inside)."""
    local = (points - pose[:2]) @ geometry.rotation(pose[2])  # R^T (p - t), row vectors
    boxes = jnp.asarray(geometry.BOXES)
    centre = jnp.stack([(boxes[:, 0] + boxes[:, 1]) / 2, (boxes[:, 2] + boxes[:, 3]) / 2], -1)
    half = jnp.stack([(boxes[:, 1] - boxes[:, 0]) / 2, (boxes[:, 3] - boxes[:, 2]) / 2], -1)
    q = jnp.abs(local[..., None, :] - centre) - half  # (..., 2 boxes, 2)
    outside = jnp.sqrt(jnp.sum(jnp.maximum(q, 0.0) ** 2, -1))
    return outside + jnp.minimum(jnp.max(q, -1), 0.0)


def scene_colour(points: jax.Array, pusher: jax.Array, pose: jax.Array, goal: jax.Array,
                 pusher_radius: float | jax.Array = 15.0) -> jax.Array:
    """float32 (..., 3): the colour of the scene at plane points (..., 2), painted in the reference's order."""
    colour = jnp.broadcast_to(jnp.asarray(WHITE, jnp.float32), points.shape[:-1] + (3,))

    def paint(mask, rgb):
        return jnp.where(mask[..., None], jnp.asarray(rgb, jnp.float32), colour)

    colour = paint(jnp.min(_box_distances(points, goal), -1) <= 0, GOAL)
    block = _box_distances(points, pose)
    colour = paint(jnp.min(block, -1) <= 0, BLOCK)
    colour = paint(jnp.min(jnp.abs(block), -1) <= OUTLINE_WIDTH, OUTLINE)
    distance = jnp.sqrt(jnp.sum((points - pusher) ** 2, -1))
    colour = paint(distance <= pusher_radius, PUSHER)
    colour = paint(distance <= pusher_radius - (15.0 - CORE_RADIUS), PUSHER_CORE)
    low, high = WALL_LINE
    x, y = points[..., 0], points[..., 1]
    span_x = (x >= low - WALL_RADIUS) & (x <= high + WALL_RADIUS)
    span_y = (y >= low - WALL_RADIUS) & (y <= high + WALL_RADIUS)
    near = lambda v, c: jnp.abs(v - c) <= WALL_RADIUS  # noqa: E731
    walls = ((near(x, low) | near(x, high)) & span_y) | ((near(y, low) | near(y, high)) & span_x)
    return paint(walls, WALL)


def render(pusher: jax.Array, pose: jax.Array, goal: jax.Array | None = None, size: int = 96, samples: int = 2,
           pusher_radius: float | jax.Array = 15.0) -> jax.Array:
    """uint8 (size, size, 3): the scene with the pusher's centre at ``pusher`` (2,) and the block at ``pose`` (3,).

    Args:
      pusher: float32 (2,), the disc's centre in the plane.
      pose: float32 (3,), the block's ``(x, y, angle)`` (body origin; see :mod:`.geometry`).
      goal: float32 (3,), the goal pose; ``pusht_env``'s when ``None``.
      size: static image side in pixels; pixel ``(row, col)`` covers the plane's square at ``(col, row)`` times
        ``512 / size``.
      samples: static points per pixel along each axis, averaged (1: the pixel's centre only).
    """
    goal = jnp.asarray(geometry.GOAL_POSE if goal is None else goal, jnp.float32)
    pixel = geometry.SIZE / size
    offsets = (np.arange(samples) + 0.5) / samples  # within a pixel
    axis = ((np.arange(size)[:, None] + offsets[None, :]) * pixel).reshape(-1).astype(np.float32)
    x, y = np.meshgrid(axis, axis)  # rows are y
    points = jnp.asarray(np.stack([x, y], -1))  # (size * samples, size * samples, 2)
    colour = scene_colour(points, jnp.asarray(pusher, jnp.float32), jnp.asarray(pose, jnp.float32), goal,
                          pusher_radius)
    colour = colour.reshape(size, samples, size, samples, 3).mean(axis=(1, 3))
    return jnp.clip(jnp.round(colour), 0, 255).astype(jnp.uint8)
