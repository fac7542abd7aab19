"""A camera for MJX physics states, rendered in JAX by casting one ray per pixel against the model's geoms.

:func:`render` draws what ``mujoco.Renderer`` draws from a model camera with its default options (geoms
and sites of groups 0-2 with a visible colour) and returns, per pixel, the colour, the depth and the object
seen. Geometry follows MuJoCo's renderer (same camera pose, field of view and pixel centres, front faces only,
surfaces nearer than its near plane clipped; depth is the distance along the camera's axis, ``far`` where
nothing is hit); appearance is an approximation: Lambert
and Blinn-Phong shading from the model's lights and headlight, geom and material colours, the floor's 2-D
texture, and a sky that shades from the skybox's darkest to its brightest colour with the ray's elevation.
No shadows, reflections or fog.

Everything is pure JAX with static shapes: ``jit`` and ``vmap`` over ``mjx.Data`` work. The scene's
constants (which objects, their types, sizes and colours) are read from the ``mujoco.MjModel`` once, by
:func:`scene_of`; positions and orientations come from the physics state (``geom_xpos``, ``geom_xmat``,
``site_xpos``, ``cam_xpos``, ...), which MJX computes for the state after each step.

Geoms: planes, spheres, capsules, ellipsoids, cylinders, boxes and meshes (:mod:`jarena.arenas.mjx.raycast`;
a mesh costs one ray-triangle test per pixel and face, so large meshes are slow). Height fields and SDF geoms
are not drawn yet: :func:`scene_of` raises naming them. Spatial tendons, which MuJoCo draws as thin capsules,
are not drawn.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct

from jarena.arenas.mjx import raycast

#: Object types in ``Frame.segmentation`` (MuJoCo's ``mjtObj`` values, as ``mujoco.Renderer``'s segmentation).
GEOM = int(mujoco.mjtObj.mjOBJ_GEOM)
SITE = int(mujoco.mjtObj.mjOBJ_SITE)

_KINDS = tuple(raycast.INTERSECT) + ("mesh",)  # drawable geom types, by name
_MJ_KIND = {int(getattr(mujoco.mjtGeom, f"mjGEOM_{k.upper()}")): k for k in _KINDS}
_VISIBLE_GROUPS = 3  # mujoco's default mjvOption draws geom and site groups 0, 1 and 2
_DEFAULT_GEOM_RGBA = (0.5, 0.5, 0.5, 1.0)  # a geom's rgba when not set: its material's colour is used


@struct.dataclass
class Frame:
    """One camera image.

    rgb: uint8 (H, W, 3).
    depth: float32 (H, W), metres along the camera's axis to the nearest surface (``far`` where none).
    segmentation: int32 (H, W, 2): ``(object id, object type)`` per pixel, the type a ``mjtObj`` value
      (``GEOM`` or ``SITE``), ``(-1, -1)`` for the background, as ``mujoco.Renderer``'s segmentation.
    """

    rgb: jax.Array
    depth: jax.Array
    segmentation: jax.Array


@dataclasses.dataclass(frozen=True, eq=False)
class Scene:
    """The static part of a model's picture: drawable objects, cameras, lights and colours (numpy arrays).

    Objects are ordered by primitive type: ``groups`` gives, per type in ``_KINDS`` order, the slice of
    objects of that type. Object ``i`` is ``object_type[i]`` (``GEOM`` or ``SITE``) number ``object_id[i]``.
    """

    groups: tuple[tuple[str, int, int], ...]  # (primitive, start, stop) over the objects
    object_type: np.ndarray  # int32 (n,)
    object_id: np.ndarray  # int32 (n,)
    kind: np.ndarray  # int32 (n,) index into _KINDS
    size: np.ndarray  # float32 (n, 3)
    rgb: np.ndarray  # float32 (n, 3)
    emission: np.ndarray  # float32 (n,)
    specular: np.ndarray  # float32 (n,)
    shininess: np.ndarray  # float32 (n,) Blinn-Phong exponent
    texture: np.ndarray  # int32 (n,): index into textures, -1 for none (planes only)
    texrepeat: np.ndarray  # float32 (n, 2) texture repeats per metre along the plane's x and y
    textures: tuple[np.ndarray, ...]  # float32 (h, w, 3) colours in [0, 1]
    meshes: tuple[np.ndarray, ...]  # per mesh object, in object order: float32 (F, 3, 3) triangles, geom frame
    camera_fovy: np.ndarray  # float32 (ncam,) degrees
    camera_names: tuple[str, ...]
    lights: dict  # numpy arrays per light field (see _lights)
    headlight: tuple[np.ndarray, np.ndarray, np.ndarray]  # ambient, diffuse, specular (3,) each
    sky: tuple[np.ndarray, np.ndarray]  # (bottom, top) rgb in [0, 1]
    far: float  # metres: depth of background pixels (MuJoCo's zfar * extent)
    near: float  # metres: surfaces nearer the camera than this are clipped (MuJoCo's znear * extent)

    @property
    def num_objects(self) -> int:
        return int(self.object_id.shape[0])

    def camera(self, camera: int | str) -> int:
        """The id of ``camera`` (a name or an id); a ``ValueError`` naming the model's cameras otherwise."""
        names = ", ".join(f"{i}: {n or '(unnamed)'}" for i, n in enumerate(self.camera_names)) or "none"
        if isinstance(camera, str) and not isinstance(camera, bool):
            if camera in self.camera_names:
                return self.camera_names.index(camera)
            if camera.lstrip("-").isdigit():
                camera = int(camera)
            else:
                raise ValueError(f"the model has no camera named {camera!r}; its cameras: {names}")
        if not isinstance(camera, int | np.integer) or isinstance(camera, bool) or not 0 <= camera < len(
                self.camera_names):
            raise ValueError(f"camera must be a model camera's name or id; got {camera!r}; the model's cameras: "
                             f"{names}")
        return int(camera)


def _texture(model: mujoco.MjModel, tex: int) -> np.ndarray:
    adr, h, w, c = (int(x[tex]) for x in (model.tex_adr, model.tex_height, model.tex_width, model.tex_nchannel))
    data = np.asarray(model.tex_data[adr:adr + h * w * c], np.float32).reshape(h, w, c) / 255.0
    if c == 1:
        data = np.repeat(data, 3, axis=-1)
    return data[..., :3]


def _sky(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """Darkest and brightest face colours of the model's skybox (a dim blue-grey gradient without one)."""
    skyboxes = [t for t in range(model.ntex) if int(model.tex_type[t]) == int(mujoco.mjtTexture.mjTEXTURE_SKYBOX)]
    if not skyboxes:
        return np.array([0.1, 0.1, 0.12], np.float32), np.array([0.4, 0.5, 0.6], np.float32)
    data = _texture(model, skyboxes[0])
    h, w = data.shape[:2]
    faces = data.reshape(h // w, w, w, 3) if h % w == 0 and h // w == 6 else data[None]
    means = faces.mean(axis=(1, 2))
    brightness = means.sum(axis=-1)
    return means[np.argmin(brightness)].astype(np.float32), means[np.argmax(brightness)].astype(np.float32)


def _appearance(model: mujoco.MjModel, rgba: np.ndarray, matid: int, size: np.ndarray):
    """``(rgb, emission, specular, shininess, texture id, texrepeat)`` of an object of colour ``rgba``."""
    if matid < 0:
        return rgba[:3], 0.0, 0.5, 0.5 * 128, -1, (1.0, 1.0)
    if np.allclose(rgba, _DEFAULT_GEOM_RGBA):
        rgba = model.mat_rgba[matid]
    tex = int(model.mat_texid[matid, int(mujoco.mjtTextureRole.mjTEXROLE_RGB)])
    if tex >= 0 and int(model.tex_type[tex]) != int(mujoco.mjtTexture.mjTEXTURE_2D):
        tex = -1
    # A plane's texture repeats texrepeat times per 2 m with texuniform (as MuJoCo draws the suite's 1 m
    # checker squares), else texrepeat times across the plane.
    repeat = np.asarray(model.mat_texrepeat[matid], np.float32)
    repeat = repeat / 2 if model.mat_texuniform[matid] else repeat / (2 * np.maximum(size[:2], 1e-6))
    return (rgba[:3], float(model.mat_emission[matid]), float(model.mat_specular[matid]),
            float(model.mat_shininess[matid]) * 128, tex, tuple(repeat))


def scene_of(model: mujoco.MjModel) -> Scene:
    """The drawable scene of ``model``: geoms and sites of groups 0-2 whose colour is not transparent.

    Raises ``NotImplementedError`` naming the visible geoms of a type the camera cannot draw yet (meshes,
    height fields, SDFs) and ``ValueError`` for orthographic cameras or cameras with sensor intrinsics.
    """
    objects = []  # (kind, object type, id, size, appearance)
    missing = []
    for kind_type, count, group, types, sizes, rgbas, matids in (
            (GEOM, model.ngeom, model.geom_group, model.geom_type, model.geom_size, model.geom_rgba, model.geom_matid),
            (SITE, model.nsite, model.site_group, model.site_type, model.site_size, model.site_rgba, model.site_matid)):
        for i in range(count):
            if not 0 <= int(group[i]) < _VISIBLE_GROUPS:
                continue
            rgba = np.asarray(rgbas[i], np.float32)
            matid = int(matids[i])
            alpha = rgba[3] if matid < 0 or not np.allclose(rgba, _DEFAULT_GEOM_RGBA) else model.mat_rgba[matid, 3]
            if alpha <= 0:
                continue
            kind = _MJ_KIND.get(int(types[i]))
            if kind is None:
                name = mujoco.mj_id2name(model, kind_type, i) or f"#{i}"
                missing.append(f"{'geom' if kind_type == GEOM else 'site'} {name!r} "
                               f"({mujoco.mjtGeom(int(types[i])).name[7:].lower()})")
                continue
            size = np.asarray(sizes[i], np.float32)
            objects.append((kind, kind_type, i, size, _appearance(model, rgba, matid, size)))
    if missing:
        raise NotImplementedError(f"the JAX camera cannot draw {', '.join(missing)} yet; it draws "
                                  f"{', '.join(_KINDS)}")
    for c in range(model.ncam):
        if int(model.cam_projection[c]) != 0 or np.any(model.cam_sensorsize[c] > 0):
            raise ValueError(f"camera {c} is orthographic or has sensor intrinsics; the JAX camera draws "
                             "perspective cameras given by fovy")
    objects.sort(key=lambda o: _KINDS.index(o[0]))
    meshes = []
    for kind, _, i, _, _ in objects:
        if kind == "mesh":
            mesh = int(model.geom_dataid[i])
            vert = model.mesh_vert[model.mesh_vertadr[mesh]:model.mesh_vertadr[mesh] + model.mesh_vertnum[mesh]]
            face = model.mesh_face[model.mesh_faceadr[mesh]:model.mesh_faceadr[mesh] + model.mesh_facenum[mesh]]
            meshes.append(np.asarray(vert[face], np.float32))
    groups, start = [], 0
    for kind in _KINDS:
        n = sum(o[0] == kind for o in objects)
        if n:
            groups.append((kind, start, start + n))
        start += n
    textures, texture_index = [], {}
    texture_of = []
    for o in objects:
        tex = o[4][4]
        if tex >= 0 and o[0] == "plane":
            if tex not in texture_index:
                texture_index[tex] = len(textures)
                textures.append(_texture(model, tex))
            texture_of.append(texture_index[tex])
        else:
            texture_of.append(-1)
    f32 = np.float32
    return Scene(
        groups=tuple(groups),
        object_type=np.array([o[1] for o in objects], np.int32).reshape(-1),
        object_id=np.array([o[2] for o in objects], np.int32).reshape(-1),
        kind=np.array([_KINDS.index(o[0]) for o in objects], np.int32).reshape(-1),
        size=np.array([o[3] for o in objects], f32).reshape(-1, 3),
        rgb=np.array([o[4][0] for o in objects], f32).reshape(-1, 3),
        emission=np.array([o[4][1] for o in objects], f32).reshape(-1),
        specular=np.array([o[4][2] for o in objects], f32).reshape(-1),
        shininess=np.array([o[4][3] for o in objects], f32).reshape(-1),
        texture=np.array(texture_of, np.int32).reshape(-1),
        texrepeat=np.array([o[4][5] for o in objects], f32).reshape(-1, 2),
        textures=tuple(textures),
        meshes=tuple(meshes),
        camera_fovy=np.asarray(model.cam_fovy, f32),
        camera_names=tuple(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_CAMERA, c) or "" for c in range(model.ncam)),
        lights=_lights(model),
        headlight=tuple(np.asarray(x, f32) for x in (model.vis.headlight.ambient, model.vis.headlight.diffuse,
                                                      model.vis.headlight.specular))
        if model.vis.headlight.active else (np.zeros(3, f32),) * 3,
        sky=_sky(model),
        far=float(model.vis.map.zfar * model.stat.extent),
        near=float(model.vis.map.znear * model.stat.extent),
    )


def _lights(model: mujoco.MjModel) -> dict:
    active = np.asarray(model.light_active, bool)
    pick = {k: np.asarray(getattr(model, f"light_{k}"))[active] for k in (
        "mode", "bodyid", "targetbodyid", "type", "pos", "dir", "pos0", "poscom0", "dir0", "ambient", "diffuse",
        "specular", "cutoff", "exponent", "attenuation")}
    pick["cos_cutoff"] = np.cos(np.deg2rad(pick.pop("cutoff"))).astype(np.float32)
    return {k: (v.astype(np.float32) if v.dtype.kind == "f" else v.astype(np.int32)) for k, v in pick.items()}


def _light_poses(scene: Scene, data) -> tuple[jax.Array, jax.Array]:
    """World positions and directions (L, 3) of the scene's lights, by their tracking modes."""
    lights = scene.lights
    if lights["mode"].size == 0:
        return jnp.zeros((0, 3)), jnp.zeros((0, 3))
    body = lights["bodyid"]
    xpos, xmat, com = data.xpos[body], data.xmat[body], data.subtree_com[body]
    fixed_pos = xpos + jnp.einsum("lij,lj->li", xmat, lights["pos"])
    fixed_dir = jnp.einsum("lij,lj->li", xmat, lights["dir"])
    mode = lights["mode"][:, None]
    Mode = mujoco.mjtCamLight
    pos = jnp.where(mode == int(Mode.mjCAMLIGHT_TRACK), xpos + lights["pos0"],
                    jnp.where(mode == int(Mode.mjCAMLIGHT_TRACKCOM), com + lights["poscom0"], fixed_pos))
    target_body = np.maximum(lights["targetbodyid"], 0)
    target = jnp.where(mode == int(Mode.mjCAMLIGHT_TARGETBODYCOM), data.subtree_com[target_body],
                       data.xpos[target_body])
    towards = target - pos
    towards = towards / jnp.maximum(jnp.linalg.norm(towards, axis=-1, keepdims=True), 1e-9)
    targeted = (mode == int(Mode.mjCAMLIGHT_TARGETBODY)) | (mode == int(Mode.mjCAMLIGHT_TARGETBODYCOM))
    direction = jnp.where(targeted, towards, jnp.where(mode == int(Mode.mjCAMLIGHT_FIXED), fixed_dir, lights["dir0"]))
    return pos, direction


def camera_rays(fovy, height: int, width: int) -> jax.Array:
    """Directions (H*W, 3) in the camera frame through pixel centres, row-major from the top-left pixel,
    scaled so the camera-frame z component is -1 (the ray parameter is the depth along the camera axis).

    MuJoCo's cameras look along their frame's -z with +y up; ``fovy`` (degrees) is the vertical field of view
    and the horizontal one follows from the aspect ratio ``width / height``.
    """
    half = jnp.tan(jnp.deg2rad(jnp.asarray(fovy, jnp.float32)) / 2)
    x = ((jnp.arange(width, dtype=jnp.float32) + 0.5) / width * 2 - 1) * half * (width / height)
    y = (1 - (jnp.arange(height, dtype=jnp.float32) + 0.5) / height * 2) * half
    xs, ys = jnp.meshgrid(x, y)
    return jnp.stack([xs.ravel(), ys.ravel(), -jnp.ones(height * width, jnp.float32)], axis=-1)


def _object_poses(scene: Scene, data) -> tuple[jax.Array, jax.Array]:
    """World positions (n, 3) and orientations (n, 3, 3) of the scene's objects."""
    is_site = scene.object_type == SITE
    geom_ids, site_ids = np.where(is_site, 0, scene.object_id), np.where(is_site, scene.object_id, 0)
    pos = jnp.where(is_site[:, None], data.site_xpos[site_ids] if data.site_xpos.shape[0] else 0.0,
                    data.geom_xpos[geom_ids])
    mat = jnp.where(is_site[:, None, None], data.site_xmat[site_ids] if data.site_xmat.shape[0] else 0.0,
                    data.geom_xmat[geom_ids])
    return pos, mat


def _texel(texture: np.ndarray, u, v) -> jax.Array:
    """Colour (..., 3) of ``texture`` at texture coordinates ``(u, v)`` (repeating, nearest texel)."""
    h, w = texture.shape[:2]
    col = jnp.floor(jnp.mod(u, 1.0) * w).astype(jnp.int32).clip(0, w - 1)
    row = jnp.floor(jnp.mod(v, 1.0) * h).astype(jnp.int32).clip(0, h - 1)
    return jnp.asarray(texture)[row, col]


def render(scene: Scene, data, camera: int, height: int, width: int) -> Frame:
    """Renders camera ``camera`` (an id, see :meth:`Scene.camera`) of one physics state at ``height x width``.

    Args:
      scene: from :func:`scene_of` of the model ``data`` belongs to (static).
      data: an ``mjx.Data`` whose kinematics are current (as after ``mjx.forward`` or an MJX arena's step).
      camera: static int, the camera's id (a ``ValueError`` for a camera the scene lacks).
      height: static int, image height in pixels (a ``ValueError`` below 1).
      width: static int, image width in pixels (a ``ValueError`` below 1).
    """
    if not isinstance(camera, int | np.integer) or not 0 <= camera < len(scene.camera_names):
        raise ValueError(f"render: camera must be an id in [0, {len(scene.camera_names)}) (Scene.camera maps "
                         f"names to ids), got {camera!r}")
    if min(height, width) < 1:
        raise ValueError(f"render: height and width must be >= 1, got {height} x {width}")
    origin = data.cam_xpos[camera]
    rays = camera_rays(scene.camera_fovy[camera], height, width) @ data.cam_xmat[camera].T  # (P, 3) world
    pos, mat = _object_poses(scene, data)

    # Nearest hit over all objects: each primitive type tests its own objects, in their frames.
    hits, mesh_normals = [], []
    for kind, start, stop in scene.groups:
        m = mat[start:stop]  # (n, 3, 3): columns are the object's axes in the world
        o_local = jnp.einsum("ni,nij->nj", origin - pos[start:stop], m)  # (n, 3)
        d_local = (rays[:, None, 0, None] * m[None, :, 0, :] + rays[:, None, 1, None] * m[None, :, 1, :]
                   + rays[:, None, 2, None] * m[None, :, 2, :])  # (P, n, 3)
        if kind == "mesh":
            for j, triangles in enumerate(scene.meshes):
                t, face = raycast.triangles(o_local[j], d_local[:, j], triangles)
                hits.append(t[:, None])
                face_normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
                mesh_normals.append(jnp.asarray(face_normals)[face])
            continue
        hits.append(raycast.INTERSECT[kind](o_local[None], d_local, jnp.asarray(scene.size[start:stop])[None]))
    if hits:
        t_all = jnp.concatenate(hits, axis=-1)  # (P, n)
        t_all = jnp.where(t_all < scene.near, jnp.inf, t_all)  # the near plane clips, as OpenGL's frustum
        nearest = jnp.argmin(t_all, axis=-1)
        t = jnp.take_along_axis(t_all, nearest[:, None], axis=-1)[:, 0]
    else:
        nearest = jnp.zeros(rays.shape[0], jnp.int32)
        t = jnp.full(rays.shape[0], jnp.inf)
    hit = jnp.isfinite(t)
    t = jnp.where(hit, t, scene.far)

    pixel_angle = 2 * jnp.tan(jnp.deg2rad(jnp.asarray(scene.camera_fovy[camera])) / 2) / height
    mesh_normal = None
    if mesh_normals:  # the winning mesh's face normal, per pixel (any mesh's where the winner is not one)
        mesh_start = next(start for kind, start, _ in scene.groups if kind == "mesh")
        which = jnp.clip(nearest - mesh_start, 0, len(mesh_normals) - 1)
        mesh_normal = jnp.take_along_axis(jnp.stack(mesh_normals, axis=1), which[:, None, None], axis=1)[:, 0]
    rgb = _shade(scene, data, origin, rays, t, nearest, hit, pos, mat, pixel_angle, mesh_normal)
    ids = jnp.where(hit, jnp.asarray(scene.object_id)[nearest] if scene.num_objects else -1, -1)
    types = jnp.where(hit, jnp.asarray(scene.object_type)[nearest] if scene.num_objects else -1, -1)
    return Frame(rgb=rgb.reshape(height, width, 3),
                 depth=t.reshape(height, width).astype(jnp.float32),
                 segmentation=jnp.stack([ids, types], axis=-1).reshape(height, width, 2).astype(jnp.int32))


def _shade(scene: Scene, data, origin, rays, t, nearest, hit, pos, mat, pixel_angle, mesh_normal) -> jax.Array:
    """uint8 (P, 3) colours of the pixels: shaded surfaces where ``hit``, the sky elsewhere (``pixel_angle``:
    radians a pixel spans)."""
    unit = rays / jnp.linalg.norm(rays, axis=-1, keepdims=True)
    bottom, top = (jnp.asarray(c) for c in scene.sky)
    sky = bottom + (top - bottom) * jnp.clip(0.5 + 0.5 * unit[:, 2:3], 0.0, 1.0)
    if not scene.num_objects:
        return jnp.round(sky * 255).astype(jnp.uint8)

    point = origin + t[:, None] * rays  # (P, 3) world
    m = mat[nearest]  # (P, 3, 3)
    local = jnp.einsum("pi,pij->pj", point - pos[nearest], m)
    size = jnp.asarray(scene.size)[nearest]
    kind = jnp.asarray(scene.kind)[nearest]
    n_local = jnp.zeros_like(local)
    for index, name in enumerate(_KINDS):
        if any(k == name for k, _, _ in scene.groups):
            normal_here = mesh_normal if name == "mesh" else raycast.normal(name, local, size)
            n_local = jnp.where((kind == index)[:, None], normal_here, n_local)
    normal = jnp.einsum("pij,pj->pi", m, n_local)
    normal = normal / jnp.maximum(jnp.linalg.norm(normal, axis=-1, keepdims=True), 1e-9)
    normal = jnp.where(jnp.sum(normal * unit, axis=-1, keepdims=True) > 0, -normal, normal)  # face the camera

    base = jnp.asarray(scene.rgb)[nearest]
    if scene.textures:
        # A pixel's footprint on the surface, in texture repeats; where it covers much of a repeat the
        # texture's mean colour stands in for one texel (as mipmapping does), so distant floors do not alias.
        repeat = jnp.asarray(scene.texrepeat)[nearest]
        slant = jnp.maximum(jnp.abs(jnp.sum(normal * unit, axis=-1)), 0.05)
        footprint = t * jnp.linalg.norm(rays, axis=-1) * pixel_angle / slant * jnp.max(repeat, axis=-1)
        blend = jnp.clip((footprint - 0.05) / 0.3, 0.0, 1.0)[:, None]
        for index, texture in enumerate(scene.textures):
            texel = _texel(texture, local[:, 0] * repeat[:, 0], -local[:, 1] * repeat[:, 1])
            texel = texel + (jnp.asarray(texture.mean(axis=(0, 1))) - texel) * blend
            base = jnp.where((jnp.asarray(scene.texture)[nearest] == index)[:, None], base * texel, base)

    view = -unit
    shininess = jnp.asarray(scene.shininess)[nearest][:, None]
    specular = jnp.asarray(scene.specular)[nearest][:, None]

    def blinn(light_dir):  # light_dir: unit vectors towards the light
        half = light_dir + view
        half = half / jnp.maximum(jnp.linalg.norm(half, axis=-1, keepdims=True), 1e-9)
        return jnp.maximum(jnp.sum(normal * half, axis=-1, keepdims=True), 0.0) ** shininess

    ambient, diffuse, spec = (jnp.asarray(x) for x in scene.headlight)
    n_dot_v = jnp.maximum(jnp.sum(normal * view, axis=-1, keepdims=True), 0.0)
    light = ambient + diffuse * n_dot_v
    shine = spec * blinn(view)
    light_pos, light_dir = _light_poses(scene, data)
    lights = scene.lights
    for i in range(lights["mode"].shape[0]):
        directional = int(lights["type"][i]) == int(mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
        if directional:
            to_light = jnp.broadcast_to(-light_dir[i], point.shape)
            spot = 1.0
        else:
            to_light = light_pos[i] - point
            to_light = to_light / jnp.maximum(jnp.linalg.norm(to_light, axis=-1, keepdims=True), 1e-9)
            cos = jnp.sum(-to_light * light_dir[i], axis=-1, keepdims=True)
            spot = 1.0
            if int(lights["type"][i]) == int(mujoco.mjtLightType.mjLIGHT_SPOT):
                spot = jnp.where(cos >= lights["cos_cutoff"][i], jnp.maximum(cos, 0.0) ** lights["exponent"][i], 0.0)
        n_dot_l = jnp.maximum(jnp.sum(normal * to_light, axis=-1, keepdims=True), 0.0)
        light = light + jnp.asarray(lights["ambient"][i]) + jnp.asarray(lights["diffuse"][i]) * n_dot_l * spot
        shine = shine + jnp.asarray(lights["specular"][i]) * blinn(to_light) * spot * (n_dot_l > 0)
    emission = jnp.asarray(scene.emission)[nearest][:, None]
    colour = base * (light + emission) + specular * shine
    colour = jnp.where(hit[:, None], colour, sky)
    return jnp.round(jnp.clip(colour, 0.0, 1.0) * 255).astype(jnp.uint8)
