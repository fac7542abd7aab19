"""Planar rigid motions of top-down images: rotated crops, yaw bins and Transporter's random SE(2) augmentation.

Pixels are ``(row, column)`` pairs, rows along the workspace's y and columns along its x (the Raven heightmap's
layout), so a yaw ``theta`` (radians, counter-clockwise about +z, as the pick-and-place primitive turns the object)
moves the offset ``(dr, dc)`` to ``(dr cos + dc sin, dc cos - dr sin)`` (:func:`rotate`). On an array printed with
row 0 on top that is a clockwise turn: a quarter turn of yaw is ``np.rot90(crop, -1)``.

Images are resampled by their nearest pixel (Ravens' ``NEAREST``); points outside the image read zeros.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

ROTATION_SIGMA = math.pi / 3
"""Standard deviation of the augmentation's rotation, radians (Ravens' ``2 pi / 6``)."""
SHIFT_SIGMA = 1 / 6
"""Standard deviation of the augmentation's translation along each axis, as a fraction of the image's shorter side."""


def rotate(offsets: jax.Array, yaw: jax.Array) -> jax.Array:
    """float32 (..., 2) pixel offsets ``(dr, dc)`` turned by ``yaw`` (radians, broadcast against ``offsets[..., 0]``)
    counter-clockwise in the workspace's x-y plane."""
    offsets = jnp.asarray(offsets, jnp.float32)
    cos, sin = jnp.cos(yaw), jnp.sin(yaw)
    dr, dc = offsets[..., 0], offsets[..., 1]
    return jnp.stack([cos * dr + sin * dc, cos * dc - sin * dr], axis=-1)


def sample_nearest(image: jax.Array, points: jax.Array) -> jax.Array:
    """Values (..., C) of ``image`` (H, W, C) at the nearest pixels of ``points`` (..., 2) ``(row, column)``; zeros
    where they fall outside the image."""
    height, width = image.shape[:2]
    index = jnp.round(points).astype(jnp.int32)
    row, col = index[..., 0], index[..., 1]
    inside = (row >= 0) & (row < height) & (col >= 0) & (col < width)
    values = image[jnp.clip(row, 0, height - 1), jnp.clip(col, 0, width - 1)]
    return jnp.where(inside[..., None], values, jnp.zeros((), image.dtype))


def rotated_crops(image: jax.Array, centre: jax.Array, yaws: jax.Array, size: int) -> jax.Array:
    """(R, size, size, C): the ``size`` x ``size`` windows of ``image`` (H, W, C) around ``centre`` (2,) ``(row,
    column)``, each showing the scene turned by one of ``yaws`` (R,) radians about ``centre``.

    Crop pixel ``(i, j)`` is the offset ``(i, j) - size // 2`` from the centre (the centre at ``(size // 2, size //
    2)``), and reads the image where that offset was before the turn: ``image[centre + rotate(offset, -yaw)]``.
    """
    grid = jnp.stack(jnp.meshgrid(jnp.arange(size), jnp.arange(size), indexing="ij"), -1) - size // 2
    sources = jnp.asarray(centre, jnp.float32) + rotate(grid[None], -jnp.asarray(yaws, jnp.float32)[:, None, None])
    return sample_nearest(image, sources)


def yaw_bins(yaw: jax.Array, rotations: int) -> jax.Array:
    """int32: the nearest of ``rotations`` yaws ``k 2 pi / rotations`` to ``yaw`` (radians), as its ``k``."""
    return jnp.mod(jnp.round(yaw / (2 * jnp.pi / rotations)).astype(jnp.int32), rotations)


def bin_yaws(rotations: int) -> jax.Array:
    """float32 (rotations,): yaw ``k`` of :func:`yaw_bins`, wrapped to [-pi, pi] (radians)."""
    yaws = jnp.arange(rotations, dtype=jnp.float32) * (2 * jnp.pi / rotations)
    return jnp.where(yaws > jnp.pi, yaws - 2 * jnp.pi, yaws)


def transform_points(points: jax.Array, angle: jax.Array, shift: jax.Array, pivot: jax.Array) -> jax.Array:
    """``points`` (..., 2) moved by the rigid motion turning ``angle`` about ``pivot`` (2,), then shifting by
    ``shift`` (2,) pixels."""
    return rotate(points - pivot, angle) + pivot + shift


def warp(image: jax.Array, angle: jax.Array, shift: jax.Array, pivot: jax.Array) -> jax.Array:
    """``image`` (H, W, C) moved by the rigid motion of :func:`transform_points`: what was at pixel ``v`` is at the
    nearest pixel to ``transform_points(v, ...)``; uncovered pixels are zeros."""
    height, width = image.shape[:2]
    grid = jnp.stack(jnp.meshgrid(jnp.arange(height), jnp.arange(width), indexing="ij"), -1).astype(jnp.float32)
    return sample_nearest(image, rotate(grid - shift - pivot, -angle) + pivot)


def random_motion(key: jax.Array, shape: tuple[int, int], points: jax.Array, tries: int = 16
                  ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Ravens' random planar motion of an image of ``shape`` (H, W) that keeps ``points`` (P, 2) in it.

    A rotation ``~ N(0, ROTATION_SIGMA)`` about the image's centre ``(H / 2, W / 2)`` and a shift ``~ N(0,
    SHIFT_SIGMA min(H, W))`` pixels along each axis, the first of ``tries`` draws that leaves every rounded point
    inside the image (Ravens draws until one does; none of ``tries`` keeps them: no motion). The shift is then
    rounded off so that the first point (the pick) lands exactly on a pixel, where the image's nearest-pixel warp
    puts its content; the others land within a pixel of theirs.

    Returns ``(angle, shift, pivot)``: float32 (), (2,), (2,).
    """
    height, width = shape
    angle_key, shift_key = jax.random.split(key)
    angles = ROTATION_SIGMA * jax.random.normal(angle_key, (tries,))
    shifts = SHIFT_SIGMA * min(height, width) * jax.random.normal(shift_key, (tries, 2))
    pivot = jnp.asarray([height / 2, width / 2], jnp.float32)
    first_point = jax.vmap(lambda a, s: transform_points(points[0], a, s, pivot))(angles, shifts)
    shifts = shifts + jnp.round(first_point) - first_point  # the first point lands on a pixel centre
    moved = jnp.round(jax.vmap(lambda a, s: transform_points(points, a, s, pivot))(angles, shifts))  # (tries, P, 2)
    upper = jnp.asarray([height - 1, width - 1], jnp.float32)
    valid = jnp.all((moved >= 0) & (moved <= upper), axis=(1, 2))
    first = jnp.argmax(valid)
    return jnp.where(valid[first], angles[first], 0.0), jnp.where(valid[first], shifts[first], jnp.zeros(2)), pivot


def augment(key: jax.Array, image: jax.Array, points: jax.Array, tries: int = 16) -> tuple[jax.Array, jax.Array]:
    """One demonstration moved by :func:`random_motion`: ``image`` (H, W, C) warped and ``points`` (P, 2) (the pick
    and place pixels) moved with it, rounded to pixels (float32 (P, 2)): the first shows the same content as before,
    the others the same or a neighbouring pixel's. A yaw between them needs no change: turning
    the whole scene turns the object and its target alike."""
    angle, shift, pivot = random_motion(key, image.shape[:2], points, tries)
    return warp(image, angle, shift, pivot), jnp.round(transform_points(points, angle, shift, pivot))
