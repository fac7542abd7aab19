"""The PushT scene's shapes, in the units of Diffusion Policy's ``pusht_env`` (a 512 x 512 plane, y down in images).

The T block is two boxes fixed in its body frame (``add_tee(scale=30, length=4)``): the bar, 120 x 30, spanning
``x in [-60, 60], y in [0, 30]``, and the stem, 30 x 90, spanning ``x in [-15, 15], y in [30, 120]``. The body's
origin (the middle of the bar's outer edge) is what ``pusht_env`` reports as the block's position; its centre of
gravity is set apart, at the mean of the two boxes' centroids, ``(0, 45)``. A pose ``(x, y, angle)`` maps a body
point ``p`` to the plane as ``R(angle) p + (x, y)``, ``R`` the counter-clockwise rotation of the plane's axes (which
draws clockwise in an image whose rows are ``y``).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

SIZE = 512.0
"""Side of the plane, in its units (pixels of the reference's window)."""

BOXES = np.array([[-60.0, 60.0, 0.0, 30.0],  # bar
                  [-15.0, 15.0, 30.0, 120.0]], np.float32)  # stem
"""float32 (2, 4): the T's boxes in its body frame, ``(x_min, x_max, y_min, y_max)`` each."""

CENTRE_OF_GRAVITY = (0.0, 45.0)
"""The T's centre of gravity in its body frame (``pusht_env``'s: the mean of the boxes' centroids, not their
area-weighted mean)."""

MASS = 1.0
INERTIA = 3000.0
"""The T's moment of inertia about its centre of gravity as ``pusht_env`` builds it: pymunk's
``moment_for_poly(1, bar)`` (about the body origin) counted twice, 1500 + 1500."""

HULL = np.array([[-60.0, 0.0], [60.0, 0.0], [60.0, 30.0], [15.0, 120.0], [-15.0, 120.0], [-60.0, 30.0]],
                np.float32)
"""float32 (6, 2): the corners of the T's convex hull in its body frame, the only points that can touch a wall
first (the stem's corners on the bar lie inside the hull)."""

KEYPOINTS = np.array([[0.0, 120.0], [-60.0, 0.0], [60.0, 15.0], [-5.0, 47.0], [12.0, 0.0], [15.0, 82.0],
                      [-24.0, 13.0], [29.0, 30.0], [-15.0, 92.0]], np.float32)
"""float32 (9, 2): keypoints of the T in its body frame, chosen as ``pusht_env``'s keypoint variant chooses
them, by farthest-point sampling over the T (here over its whole-unit grid points, from the stem's tip): they
spread over the T and fix its pose. The reference's own nine come from a seeded draw over rendered pixels and
differ."""

AREA = float(np.sum((BOXES[:, 1] - BOXES[:, 0]) * (BOXES[:, 3] - BOXES[:, 2])))
"""The T's area, 6300 square units."""

GOAL_POSE = (256.0, 256.0, math.pi / 4)
"""The goal pose ``(x, y, angle)`` of ``pusht_env``."""


def rotation(angle: jax.Array) -> jax.Array:
    """float32 (..., 2, 2): ``R(angle)`` for angles of shape (...)."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.stack([jnp.stack([c, -s], -1), jnp.stack([s, c], -1)], -2)


def to_plane(pose: jax.Array, points: jax.Array) -> jax.Array:
    """Body-frame points (..., 2) in the plane, for a pose (3,) ``(x, y, angle)``."""
    pose = jnp.asarray(pose, jnp.float32)
    return jnp.asarray(points, jnp.float32) @ rotation(pose[2]).T + pose[:2]


def box_corners(boxes: np.ndarray = BOXES) -> np.ndarray:
    """float32 (N, 4, 2): each box's corners in the body frame, counter-clockwise (x right, y up)."""
    x0, x1, y0, y1 = (boxes[:, i] for i in range(4))
    return np.stack([np.stack([x0, y0], -1), np.stack([x1, y0], -1), np.stack([x1, y1], -1),
                     np.stack([x0, y1], -1)], 1).astype(np.float32)


def keypoints(pose: jax.Array) -> jax.Array:
    """float32 (9, 2): :data:`KEYPOINTS` in the plane for a block pose (3,)."""
    return to_plane(pose, KEYPOINTS)
