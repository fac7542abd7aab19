"""Rigid poses for the tabletop: positions (3,) in metres and unit quaternions (4,) ``(w, x, y, z)``, MuJoCo's order.

Tabletop objects stand upright, so most of the family works with planar poses: ``(x, y, yaw)``, yaw in radians
about +z. Every function broadcasts over leading axes.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def yaw_quat(yaw: jax.Array) -> jax.Array:
    """float32 (..., 4): the rotation by ``yaw`` radians about +z."""
    half = 0.5 * jnp.asarray(yaw, jnp.float32)
    zero = jnp.zeros_like(half)
    return jnp.stack([jnp.cos(half), zero, zero, jnp.sin(half)], axis=-1)


def quat_mul(a: jax.Array, b: jax.Array) -> jax.Array:
    """The Hamilton product ``a b`` (rotate by ``b``, then by ``a``)."""
    aw, ax, ay, az = (a[..., i] for i in range(4))
    bw, bx, by, bz = (b[..., i] for i in range(4))
    return jnp.stack([aw * bw - ax * bx - ay * by - az * bz,
                      aw * bx + ax * bw + ay * bz - az * by,
                      aw * by - ax * bz + ay * bw + az * bx,
                      aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def quat_conj(q: jax.Array) -> jax.Array:
    """The inverse of a unit quaternion."""
    return q * jnp.asarray([1.0, -1.0, -1.0, -1.0], q.dtype)


def rotate(q: jax.Array, v: jax.Array) -> jax.Array:
    """``v`` (..., 3) rotated by the unit quaternion ``q`` (..., 4)."""
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * jnp.cross(u, v)
    return v + w * t + jnp.cross(u, t)


def compose(pos_a, quat_a, pos_b, quat_b) -> tuple[jax.Array, jax.Array]:
    """Pose ``a`` followed by ``b`` in its frame: ``(pos_a + R_a pos_b, q_a q_b)``."""
    return pos_a + rotate(quat_a, pos_b), quat_mul(quat_a, quat_b)


def relative(pos_a, quat_a, pos_b, quat_b) -> tuple[jax.Array, jax.Array]:
    """Pose ``b`` in the frame of pose ``a``: ``a^-1 b``."""
    inverse = quat_conj(quat_a)
    return rotate(inverse, pos_b - pos_a), quat_mul(inverse, quat_b)


def yaw_of(quat: jax.Array) -> jax.Array:
    """float32 (...): the heading of ``quat``'s x axis about +z, radians in (-pi, pi] (Ravens' Euler-XYZ yaw for
    upright objects)."""
    w, x, y, z = (quat[..., i] for i in range(4))
    return jnp.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def wrap_angle(angle: jax.Array) -> jax.Array:
    """``angle`` wrapped to [-pi, pi)."""
    return jnp.mod(angle + jnp.pi, 2.0 * jnp.pi) - jnp.pi


def planar(pos: jax.Array, quat: jax.Array) -> jax.Array:
    """float32 (..., 4): ``(x, y, z, yaw)`` of a pose."""
    return jnp.concatenate([pos, yaw_of(quat)[..., None]], axis=-1)
