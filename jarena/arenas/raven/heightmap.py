"""Ravens' top-down orthographic heightmap, rendered exactly on the device by one vertical ray per pixel.

The workspace is x in [0.25, 0.75] m, y in [-0.5, 0.5] m, z in [0, 0.28] m; a pixel is 3.125 mm, so the image is
320 rows (along y) by 160 columns (along x), Ravens' and Transporter's ``(320, 160)`` layout: row ``r``, column ``c``
is the point ``x = 0.25 + (c + 0.5) p``, ``y = -0.5 + (r + 0.5) p`` (the pixel's centre; :func:`pixel_to_world`,
:func:`world_to_pixel`). Each pixel holds the height (metres above the table, clipped to the workspace's 0.28 m)
and the flat colour of the highest surface at that point, and the object seen there (-1 for the table), which
oracles read as Ravens' segmentation mask. Ravens fuses three simulated RGB-D cameras into this map; here it is
rendered directly, without noise, shading or occlusion gaps.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.mjx.raycast import box as raycast_box
from jarena.arenas.raven import geometry
from jarena.arenas.raven.scene import TABLE_RGB, Scene

PIXEL_SIZE = 0.003125
"""Metres per pixel."""
BOUNDS = ((0.25, 0.75), (-0.5, 0.5), (0.0, 0.28))
"""The workspace: (x, y, z) ranges, metres."""
ROWS = int(round((BOUNDS[1][1] - BOUNDS[1][0]) / PIXEL_SIZE))  # 320, along y
COLS = int(round((BOUNDS[0][1] - BOUNDS[0][0]) / PIXEL_SIZE))  # 160, along x


def pixel_to_world(rc: jax.Array) -> jax.Array:
    """float32 (..., 2) ``(x, y)`` metres of pixel coordinates ``rc`` (..., 2) ``(row, column)`` (fractional rows and
    columns name points between pixel centres)."""
    rc = jnp.asarray(rc, jnp.float32)
    return jnp.stack([BOUNDS[0][0] + (rc[..., 1] + 0.5) * PIXEL_SIZE,
                      BOUNDS[1][0] + (rc[..., 0] + 0.5) * PIXEL_SIZE], axis=-1)


def world_to_pixel(xy: jax.Array) -> jax.Array:
    """float32 (..., 2) ``(row, column)`` of points ``xy`` (..., 2), the inverse of :func:`pixel_to_world`."""
    xy = jnp.asarray(xy, jnp.float32)
    return jnp.stack([(xy[..., 1] - BOUNDS[1][0]) / PIXEL_SIZE - 0.5,
                      (xy[..., 0] - BOUNDS[0][0]) / PIXEL_SIZE - 0.5], axis=-1)


def pixel_centres() -> np.ndarray:
    """float32 (ROWS, COLS, 2): every pixel's centre ``(x, y)``, metres."""
    rows, cols = np.meshgrid(np.arange(ROWS), np.arange(COLS), indexing="ij")
    return np.stack([BOUNDS[0][0] + (cols + 0.5) * PIXEL_SIZE, BOUNDS[1][0] + (rows + 0.5) * PIXEL_SIZE],
                    -1).astype(np.float32)


@struct.dataclass
class Heightmap:
    """One top-down view. ``rgb`` uint8 (ROWS, COLS, 3); ``height`` float32 (ROWS, COLS), metres above the table;
    ``object`` int32 (ROWS, COLS), the object seen (its index in the scene), -1 for the table."""

    rgb: jax.Array
    height: jax.Array
    object: jax.Array


def window(scene: Scene) -> int:
    """The side, in pixels, of the square around a box's centre that holds every pixel it can cover in any
    orientation (its diagonal, and a pixel for rounding; a resizable shape's boxes are at most the scene's)."""
    diagonal = 2.0 * float(np.max(np.linalg.norm(scene.geom_size, axis=-1)))
    return int(np.ceil(diagonal / PIXEL_SIZE)) + 2


def render(scene: Scene, geom_xpos: jax.Array, geom_xmat: jax.Array, geom_size: jax.Array | None = None,
           geom_rgb: jax.Array | None = None) -> Heightmap:
    """The heightmap of a scene whose geoms are at ``geom_xpos`` (ngeom, 3) and ``geom_xmat`` (ngeom, 9) (an
    ``mjx.Data``'s, after kinematics), its drawable boxes of half extents ``geom_size`` (G, 3) and colours
    ``geom_rgb`` (G, 3) (``None``: the scene's; a :class:`.physics.RavenPhysics` holds the episode's); the
    suction cup is not drawn.

    Each box casts rays only through the pixels of a square around its centre (:func:`window`), and the highest
    hit wins each pixel (ties to the box listed last), so the work grows with the boxes' area, not the image's.
    """
    geoms = jnp.asarray(scene.geom)
    pos, mat = geom_xpos[geoms], geom_xmat[geoms].reshape(-1, 3, 3)
    size = jnp.asarray(scene.geom_size if geom_size is None else geom_size, jnp.float32)
    side = window(scene)
    offsets = jnp.arange(side) - side // 2
    centre = jnp.round(world_to_pixel(pos[:, :2])).astype(jnp.int32)  # (G, 2)
    rows = centre[:, 0, None, None] + offsets[None, :, None]  # (G, side, 1)
    cols = centre[:, 1, None, None] + offsets[None, None, :]  # (G, 1, side)
    rows, cols = jnp.broadcast_arrays(rows, cols)  # (G, side, side)
    inside = (rows >= 0) & (rows < ROWS) & (cols >= 0) & (cols < COLS)
    xy = pixel_to_world(jnp.stack([rows, cols], -1).astype(jnp.float32))  # (G, side, side, 2)
    origin = jnp.concatenate([xy, jnp.full(xy.shape[:-1] + (1,), geometry.SKY, jnp.float32)], -1)
    local = jnp.einsum("gji,gabj->gabi", mat, origin - pos[:, None, None, :])
    direction = jnp.broadcast_to(-mat[:, None, None, 2, :], local.shape)
    t = raycast_box(local, direction, jnp.broadcast_to(size[:, None, None, :], local.shape))
    hit = inside & jnp.isfinite(t) & (t < geometry.SKY)
    height = jnp.where(hit, geometry.SKY - t, 0.0)
    flat = jnp.where(inside, rows * COLS + cols, ROWS * COLS)  # outside the image: dropped
    top = jnp.zeros(ROWS * COLS, jnp.float32).at[flat.reshape(-1)].max(height.reshape(-1), mode="drop")
    box_id = jnp.broadcast_to(jnp.arange(geoms.shape[0], dtype=jnp.int32)[:, None, None], flat.shape)
    wins = hit & (height >= top[jnp.minimum(flat, ROWS * COLS - 1)]) & (height > 0)
    box = jnp.full(ROWS * COLS, -1, jnp.int32).at[jnp.where(wins, flat, ROWS * COLS).reshape(-1)].max(
        box_id.reshape(-1), mode="drop")
    colours = jnp.concatenate([jnp.asarray(scene.geom_rgb if geom_rgb is None else geom_rgb, jnp.float32),
                               jnp.asarray([TABLE_RGB], jnp.float32)])
    rgb = jnp.round(colours[box] * 255.0).astype(jnp.uint8)  # box -1 takes the last row: the table
    objects = jnp.where(box >= 0, jnp.asarray(scene.geom_object)[box], -1)
    height = jnp.clip(top, BOUNDS[2][0], BOUNDS[2][1])
    return Heightmap(rgb=rgb.reshape(ROWS, COLS, 3), height=height.reshape(ROWS, COLS),
                     object=objects.reshape(ROWS, COLS).astype(jnp.int32))
