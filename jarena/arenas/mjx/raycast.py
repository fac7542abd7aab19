"""Ray intersections with MuJoCo's geometric primitives, in the primitive's own frame.

Every function takes ray origins ``o`` and directions ``d`` (float arrays broadcasting to (..., 3), metres,
``d`` need not be unit length) and the primitive's ``size`` as MuJoCo defines it (``geom_size``: sphere
``(r, _, _)``, capsule and cylinder ``(r, half_length, _)``, ellipsoid and box ``(a, b, c)`` half-extents,
plane ``(half_x, half_y, _)`` with 0 meaning unbounded), broadcasting to the rays' leading shape. They
return the ray parameter ``t`` of the nearest hit in front of the origin (``t > 0``; the hit point is
``o + t d``), or ``+inf`` where the ray misses. Only front faces count, as in MuJoCo's renderer, which culls
back faces: a ray that starts inside a primitive does not see it (a camera inside a head sees out of it).
Pure ``jnp``: ``jit``, ``vmap`` and broadcasting work.

Conventions follow MuJoCo: capsules and cylinders lie along the local z axis, planes are the local
``z = 0`` plane seen from ``z > 0`` (their front, where the normal points), boxes and ellipsoids are
axis-aligned in the local frame.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

INF = jnp.inf
_EPS = 1e-12


def _entry(t_near, hit):
    """``t_near``, where the ray enters the primitive in front of its origin, else ``inf``."""
    return jnp.where(hit & (t_near > 0), t_near, INF)


def _quadratic(a, b, c):
    """Roots of ``a t^2 + 2 b t + c = 0`` as ``(t_near, t_far, real)`` (``a > 0``)."""
    disc = b * b - a * c
    real = disc >= 0
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
    a = jnp.maximum(a, _EPS)
    return (-b - root) / a, (-b + root) / a, real


def _dot(u, v):
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1] + u[..., 2] * v[..., 2]


def sphere(o, d, size):
    """Sphere of radius ``size[..., 0]`` around the origin."""
    r = size[..., 0]
    t0, _, real = _quadratic(_dot(d, d), _dot(o, d), _dot(o, o) - r * r)
    return _entry(t0, real)


def ellipsoid(o, d, size):
    """Ellipsoid of half-axes ``size`` (the unit sphere scaled by ``size``)."""
    inv = 1.0 / size
    return sphere(o * inv, d * inv, jnp.ones_like(size))


def _side(o, d, r, h):
    """The infinite cylinder ``x^2 + y^2 = r^2`` cut to ``|z| <= h``."""
    a = d[..., 0] ** 2 + d[..., 1] ** 2
    b = o[..., 0] * d[..., 0] + o[..., 1] * d[..., 1]
    c = o[..., 0] ** 2 + o[..., 1] ** 2 - r * r
    t0, _, real = _quadratic(a, b, c)
    within = real & (a > _EPS) & (t0 > 0) & (jnp.abs(o[..., 2] + t0 * d[..., 2]) <= h)
    return jnp.where(within, t0, INF)


def capsule(o, d, size):
    """Capsule of radius ``size[..., 0]`` around the segment ``|z| <= size[..., 1]``."""
    r, h = size[..., 0], size[..., 1]
    ends = jnp.stack([jnp.zeros_like(h), jnp.zeros_like(h), h], axis=-1)
    caps = jnp.minimum(sphere(o - ends, d, size), sphere(o + ends, d, size))
    return jnp.minimum(_side(o, d, r, h), caps)


def _safe(x):
    """``x`` with magnitudes below 1e-12 replaced by +-1e-12 (a ray parallel to an axis plane)."""
    return jnp.where(jnp.abs(x) < _EPS, jnp.where(x < 0, -_EPS, _EPS), x)


def cylinder(o, d, size):
    """Cylinder of radius ``size[..., 0]`` and half-length ``size[..., 1]`` along z, with flat caps."""
    r, h = size[..., 0], size[..., 1]
    dz = _safe(d[..., 2])
    best = _side(o, d, r, h)
    for sign in (-1.0, 1.0):  # a cap faces out: the ray enters through it moving against its normal
        t = (sign * h - o[..., 2]) / dz
        x, y = o[..., 0] + t * d[..., 0], o[..., 1] + t * d[..., 1]
        front = sign * d[..., 2] < 0
        best = jnp.minimum(best, jnp.where(front & (t > 0) & (x * x + y * y <= r * r), t, INF))
    return best


def box(o, d, size):
    """Box of half-extents ``size`` (slab test)."""
    inv = 1.0 / _safe(d)
    t1, t2 = (-size - o) * inv, (size - o) * inv
    t_near = jnp.max(jnp.minimum(t1, t2), axis=-1)
    t_far = jnp.min(jnp.maximum(t1, t2), axis=-1)
    return _entry(t_near, t_near <= t_far)


def plane(o, d, size):
    """The plane ``z = 0`` within ``|x| <= size[..., 0]`` and ``|y| <= size[..., 1]`` (0: unbounded), hit
    from its front (``z > 0``) only, as MuJoCo's planes."""
    dz = d[..., 2]
    t = -o[..., 2] / jnp.where(dz < 0, dz, -1.0)
    x, y = o[..., 0] + t * d[..., 0], o[..., 1] + t * d[..., 1]
    sx, sy = size[..., 0], size[..., 1]
    inside = ((sx <= 0) | (jnp.abs(x) <= sx)) & ((sy <= 0) | (jnp.abs(y) <= sy))
    return jnp.where((dz < 0) & (o[..., 2] > 0) & inside & (t > 0), t, INF)


def normal(kind: str, p, size) -> jax.Array:
    """Unnormalised outward normal at a point ``p`` (..., 3) on a primitive of type ``kind``.

    ``kind`` is one of ``INTERSECT``'s keys. For cylinders and boxes the face is the one whose signed
    distance is largest (the gradient of the primitive's distance function).
    """
    zero = jnp.zeros_like(p[..., 0])
    if kind == "plane":
        return jnp.stack([zero, zero, jnp.ones_like(zero)], axis=-1)
    if kind == "sphere":
        return p
    if kind == "ellipsoid":
        return p / (size * size)
    if kind == "capsule":
        h = size[..., 1]
        return p - jnp.stack([zero, zero, jnp.clip(p[..., 2], -h, h)], axis=-1)
    if kind == "cylinder":
        r, h = size[..., 0], size[..., 1]
        radial = jnp.sqrt(p[..., 0] ** 2 + p[..., 1] ** 2)
        on_cap = jnp.abs(p[..., 2]) - h > radial - r
        side = jnp.stack([p[..., 0], p[..., 1], zero], axis=-1)
        cap = jnp.stack([zero, zero, jnp.sign(p[..., 2])], axis=-1)
        return jnp.where(on_cap[..., None], cap, side)
    if kind == "box":
        excess = jnp.abs(p) - size
        face = jax.nn.one_hot(jnp.argmax(excess, axis=-1), 3, dtype=p.dtype)
        return face * jnp.sign(p)
    raise ValueError(f"unknown primitive {kind!r}; choose from {', '.join(INTERSECT)}")


#: Intersection function of each primitive, by MuJoCo's geom type name (``mjtGeom`` without ``mjGEOM_``,
#: lower case).
INTERSECT = {"plane": plane, "sphere": sphere, "capsule": capsule, "ellipsoid": ellipsoid,
             "cylinder": cylinder, "box": box}


def triangles(o, d, vertices) -> tuple[jax.Array, jax.Array]:
    """Nearest front-facing triangle of a mesh hit by each ray (Moller-Trumbore).

    Args:
      o: ray origins, (..., 3), in the mesh's frame.
      d: ray directions, (..., 3), in the mesh's frame.
      vertices: (F, 3, 3) triangles, counter-clockwise seen from their front (MuJoCo's outward faces).
    Returns:
      ``(t, face)``: (...) the ray parameter of the nearest hit (``inf`` for none) and (...) int32 the index of
      that triangle (0 where none).
    """
    v0, e1, e2 = (jnp.asarray(x, jnp.float32) for x in (vertices[:, 0], vertices[:, 1] - vertices[:, 0],
                                                          vertices[:, 2] - vertices[:, 0]))
    o, d = o[..., None, :], d[..., None, :]  # (..., 1, 3) against (F, 3)
    pvec = jnp.cross(d, e2)
    det = _dot(e1, pvec)
    front = det > _EPS  # the ray meets the face against its normal cross(e1, e2)
    inv = 1.0 / jnp.where(front, det, 1.0)
    tvec = o - v0
    u = _dot(tvec, pvec) * inv
    qvec = jnp.cross(tvec, e1)
    v = _dot(d, qvec) * inv
    t = _dot(e2, qvec) * inv
    hit = front & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    t = jnp.where(hit, t, INF)
    face = jnp.argmin(t, axis=-1).astype(jnp.int32)
    return jnp.min(t, axis=-1), face
