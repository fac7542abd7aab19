"""SoftGym's top-down camera over the cloth: projection, rendering (colour, depth, mask) and particle visibility.

The camera hangs ``height`` metres above the world origin looking straight down (-z) with a square image
and a field of view of ``fov`` degrees both ways; image right is world +x and image up is world +y. Image
points are normalised coordinates ``uv`` in ``[-1, 1]^2``: ``u`` from the left column to the right one,
``v`` from the top row to the bottom one. Pixel ``(r, c)`` of an ``R x R`` image has its centre at
``uv = ((c + 0.5) / R * 2 - 1, (r + 0.5) / R * 2 - 1)``. With ``t = tan(fov / 2)``, a point ``(x, y, z)``
is at depth ``d = height - z`` along the camera's axis and projects to ``u = x / (d t)``, ``v = -y / (d t)``;
at 1.5 m and 45 degrees the image spans about +-0.62 m on the floor, as SoftGym's does.

Rendering rasterises the mesh's triangles with :mod:`jarena.arenas.cloth.raster` (perspective-correct depth,
a z-buffer on inverse depth): the cloth's front colour where the visible side of the triangle is its front
(the triangle normal ``cross(b - a, c - a)`` points towards the camera; up for the flat cloth), the back
colour where it is the back (a layer folded over shows its back), each Lambert-shaded with a light at the
camera: ``ambient + (1 - ambient) * |n . view|``. The floor (z = 0) is drawn flat in its colour at depth
``height``. Everything is pure JAX with static shapes: ``jit`` and ``vmap`` (over positions and params) work.

Window (see ``raster``): a triangle of the grid mesh has edges at most ``L = stretch * sqrt(2) * spacing``
(the cell diagonal, stretched), and a segment of length ``L`` at depth ``d >= height - max_z`` inside the
view spans at most ``L * sqrt(1 + t**2) * R / (2 t (height - max_z))`` pixels along either image axis
(``du = (dx + (x / d) dz) / (d t)`` with ``|x / d| <= t``). :func:`render_window` returns ``floor`` of that
plus one, from the default camera, ``stretch = 1.5`` and ``max_z = 0.5`` m unless told otherwise. Pixels of
triangles larger than that (stretched further, or nearer the camera, or a camera set lower or wider than
the window was computed for) are missed; pass ``window`` explicitly for such cases.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.cloth import raster
from jarena.arenas.cloth.mesh import ClothMesh

DEFAULT_HEIGHT = 1.5  # metres above the floor
DEFAULT_FOV = 45.0  # degrees, vertical = horizontal
NEAR = 0.1  # triangles with a vertex nearer than NEAR * height to the camera (or behind it) are not drawn
FAR = 2.0  # inverse depth is quantised for the z-buffer between depths NEAR * height and FAR * height


def _f32(*values):
    return lambda: jnp.asarray(values if len(values) > 1 else values[0], jnp.float32)


@struct.dataclass
class CameraParams:
    """The camera and the colours it draws; every leaf is float32 so batches of params ``vmap``.

    height: () metres of the camera above the floor (the camera is above the world origin).
    fov: () field of view in degrees, the same vertically and horizontally (square images).
    front_rgb: (3,) colour in [0, 1] of the cloth's front face (up when flat).
    back_rgb: (3,) colour in [0, 1] of the cloth's back face.
    floor_rgb: (3,) colour in [0, 1] of the floor.
    ambient: () fraction of the light that does not depend on the surface's slant.
    """

    height: jax.Array = struct.field(default_factory=_f32(DEFAULT_HEIGHT))
    fov: jax.Array = struct.field(default_factory=_f32(DEFAULT_FOV))
    front_rgb: jax.Array = struct.field(default_factory=_f32(0.93, 0.62, 0.24))  # warm amber
    back_rgb: jax.Array = struct.field(default_factory=_f32(0.27, 0.53, 0.82))  # steel blue
    floor_rgb: jax.Array = struct.field(default_factory=_f32(0.22, 0.22, 0.23))  # dark grey
    ambient: jax.Array = struct.field(default_factory=_f32(0.35))


def _tan_half(params: CameraParams):
    return jnp.tan(jnp.deg2rad(jnp.asarray(params.fov, jnp.float32)) / 2)


def pixel_to_world(uv, z, params: CameraParams) -> jax.Array:
    """World ``(x, y)`` where the ray through image point ``uv`` meets the plane at height ``z``.

    Args:
      uv: float (..., 2) normalised image coordinates in [-1, 1] (u: left to right, v: top to bottom).
      z: float (...) or scalar height of the plane, metres.
    Returns:
      float32 (..., 2) metres: ``x = u (H - z) t``, ``y = -v (H - z) t`` with ``t = tan(fov / 2)``.
    """
    uv = jnp.asarray(uv, jnp.float32)
    s = (params.height - jnp.asarray(z, jnp.float32)) * _tan_half(params)
    return jnp.stack([uv[..., 0] * s, -uv[..., 1] * s], -1)


def world_to_pixel(xyz, params: CameraParams) -> jax.Array:
    """float32 (..., 2): normalised image coordinates ``uv`` of world points ``xyz`` (..., 3) in metres
    (the inverse of :func:`pixel_to_world`; points below the camera only)."""
    xyz = jnp.asarray(xyz, jnp.float32)
    s = (params.height - xyz[..., 2]) * _tan_half(params)
    return jnp.stack([xyz[..., 0] / s, -xyz[..., 1] / s], -1)


def uv_to_pixel(uv, resolution: int) -> jax.Array:
    """float32 (..., 2): pixel coordinates ``(column, row)`` (continuous; pixel ``(r, c)`` spans
    ``[c, c + 1) x [r, r + 1)``) of normalised image points ``uv`` in an ``R x R`` image."""
    return (jnp.asarray(uv, jnp.float32) + 1.0) * (resolution / 2.0)


def render_window(mesh: ClothMesh, resolution: int, height: float = DEFAULT_HEIGHT, fov: float = DEFAULT_FOV,
                  stretch: float = 1.5, max_z: float = 0.5) -> int:
    """Static raster window (pixels per side) for ``mesh`` at ``resolution``: ``floor(e) + 1`` with
    ``e = stretch * sqrt(2) * spacing * sqrt(1 + t^2) * R / (2 t (height - max_z))``, ``t = tan(fov / 2)``.

    Triangles stretched beyond ``stretch`` or with a vertex above ``max_z`` metres may lose pixels."""
    if not height - max_z > 0:
        raise ValueError(f"max_z ({max_z}) must be below the camera height ({height})")
    t = math.tan(math.radians(fov) / 2)
    edge = stretch * math.sqrt(2.0) * mesh.spacing
    extent = edge * math.sqrt(1 + t * t) * resolution / (2 * t * (height - max_z))
    return raster.window_for(extent)


def _project(positions, params: CameraParams):
    """uv (N, 2), depth along the axis (N,) of particles (N, 3)."""
    positions = jnp.asarray(positions, jnp.float32)
    return world_to_pixel(positions, params), params.height - positions[:, 2]


def _dot3(a, b):
    """Sum over the last axis (of size 3) written out: one fixed order of operations in every program, so
    a batch of one rounds exactly like a batch of many (a reduction may be reordered by XLA)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _unit(v):
    norm = jnp.sqrt(_dot3(v, v))[..., None]
    return v / jnp.where(norm > 0, norm, 1.0)


def _triangle_normals(positions, triangles):
    """float32 (T, 3) unit normals ``cross(b - a, c - a)`` (zero for degenerate triangles)."""
    p = positions[triangles]
    return _unit(jnp.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))


def _rasterize(positions, mesh: ClothMesh, params: CameraParams, resolution: int, window: int | None):
    """The z-buffered raster of the cloth: (Raster, float32 (R, R) depth of the cloth where it is drawn)."""
    resolution = int(resolution)
    if window is None:
        window = render_window(mesh, resolution)
    tris = jnp.asarray(mesh.triangles)
    uv, depth = _project(positions, params)
    near, far = NEAR * params.height, FAR * params.height
    inv = 1.0 / jnp.maximum(depth, near)  # inverse depth is linear in image space over a triangle
    xy = uv_to_pixel(uv, resolution)[tris]  # (T, 3, 2)
    valid = jnp.all(depth[tris] > near, axis=1)
    # z-buffer key: minus inverse depth (nearest smallest), quantised between 1 / near and 1 / far.
    ras = raster.rasterize(xy, -inv[tris], (resolution, resolution), window, (-1.0 / near, -1.0 / far), valid)
    inv_px = _dot3(ras.bary, inv[tris][jnp.maximum(ras.tri_id, 0)])  # perspective-correct interpolation
    cloth_depth = 1.0 / jnp.where(ras.tri_id >= 0, inv_px, 1.0)
    return ras, cloth_depth


def pixel_uv(resolution: int) -> jax.Array:
    """float32 (R, R, 2): normalised image coordinates of the pixel centres, ``[r, c] = (u_c, v_r)``."""
    centres = (jnp.arange(resolution, dtype=jnp.float32) + 0.5) / resolution * 2 - 1
    v, u = jnp.meshgrid(centres, centres, indexing="ij")
    return jnp.stack([u, v], -1)


def render(positions, mesh: ClothMesh, params: CameraParams, resolution: int, window: int | None = None) -> dict:
    """Renders the cloth from above.

    Args:
      positions: float32 (N, 3) particle positions, metres, world z-up (N = mesh.num_particles).
      mesh: the cloth's mesh (static).
      params: the camera and colours.
      resolution: static image size R (the image is R x R).
      window: static raster window; default :func:`render_window` (mesh, R) (see the module doc).
    Returns:
      dict with ``rgb`` uint8 (R, R, 3), ``depth`` float32 (R, R) metres from the camera along its axis
      (``height - z`` of the visible surface; the floor's is ``height``), ``mask`` bool (R, R) (cloth).
    """
    resolution = int(resolution)
    ras, cloth_depth = _rasterize(positions, mesh, params, resolution, window)
    mask = ras.tri_id >= 0
    normals = _triangle_normals(jnp.asarray(positions, jnp.float32), jnp.asarray(mesh.triangles))
    n = normals[jnp.maximum(ras.tri_id, 0)]  # (R, R, 3)
    t = _tan_half(params)
    uv = pixel_uv(resolution)
    view = jnp.concatenate([-uv[..., :1] * t, uv[..., 1:] * t, jnp.ones_like(uv[..., :1])], -1)
    cos = _dot3(n, _unit(view))  # view: from the surface towards the camera
    shade = params.ambient + (1 - params.ambient) * jnp.abs(cos)
    colour = jnp.where((cos >= 0)[..., None], params.front_rgb, params.back_rgb) * shade[..., None]
    rgb = jnp.where(mask[..., None], colour, params.floor_rgb)
    rgb = jnp.round(jnp.clip(rgb, 0.0, 1.0) * 255).astype(jnp.uint8)
    depth = jnp.where(mask, cloth_depth, params.height).astype(jnp.float32)
    return {"rgb": rgb, "depth": depth, "mask": mask}


def visible(positions, mesh: ClothMesh, indices, params: CameraParams, resolution: int | None = None, *,
            tol: float | None = None) -> jax.Array:
    """bool (K,): whether each particle ``indices`` (int (K,)) is on the surface the camera sees.

    A particle is visible when it projects inside the image (``|u|, |v| <= 1``, below the camera) and no
    triangle of the cloth covers it from the camera by more than ``tol`` metres of depth, not counting the
    triangles that touch the particle or its grid neighbours (its own surface). The test is exact in
    continuous image coordinates (each particle against every triangle, O(K T) work), so it does not
    depend on a resolution: ``resolution`` is accepted for callers of a pixel-based definition and unused.

    Args:
      positions: float32 (N, 3) particle positions, metres.
      mesh: the cloth's mesh (static).
      indices: int (K,) flat particle indices, e.g. ``mesh.corners``.
      params: the camera.
      tol: depth margin, metres; default half the mesh spacing. A layer less than ``tol`` above the
        particle does not hide it.
    """
    del resolution
    tol = 0.5 * mesh.spacing if tol is None else tol
    positions = jnp.asarray(positions, jnp.float32)
    indices = jnp.asarray(indices, jnp.int32)
    tris = np.asarray(mesh.triangles)
    uv, depth = _project(positions, params)
    near = NEAR * params.height
    inv = 1.0 / jnp.maximum(depth, near)
    valid = jnp.all(depth[tris] > near, axis=1)  # (T,)

    puv, pdepth = uv[indices], depth[indices]  # (K, 2), (K,)
    tuv = uv[tris]  # (T, 3, 2)
    w0, w1, w2 = raster.edge_functions(puv[:, None, :], tuv[None, :, 0], tuv[None, :, 1], tuv[None, :, 2])  # (K, T)
    area = w0 + w1 + w2
    safe = jnp.where(area == 0, 1.0, area)
    tinv = inv[tris]
    inv_hit = (w0 * tinv[None, :, 0] + w1 * tinv[None, :, 1] + w2 * tinv[None, :, 2]) / safe
    hit_depth = 1.0 / jnp.maximum(inv_hit, 1e-6)
    # Triangles with a vertex within one grid step of the particle are its own surface.
    ti, tj = np.divmod(tris, mesh.cols)  # (T, 3)
    pi, pj = jnp.divmod(indices, mesh.cols)  # (K,)
    near_grid = (jnp.abs(ti[None] - pi[:, None, None]) <= 1) & (jnp.abs(tj[None] - pj[:, None, None]) <= 1)
    own = jnp.any(near_grid, axis=-1)  # (K, T)
    covers = raster.inside(w0, w1, w2) & valid[None] & ~own & (hit_depth < pdepth[:, None] - tol)
    in_image = jnp.all(jnp.abs(puv) <= 1.0, axis=-1) & (pdepth > near)
    return in_image & ~jnp.any(covers, axis=-1)
