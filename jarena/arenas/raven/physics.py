"""The tabletop's dynamics on MJX: objects under gravity and contact, and a floating suction cup moved kinematically.

One control step (``control`` float32 (6,), :data:`CONTROL_FIELDS`) moves the cup, then runs ``substeps`` MJX
physics steps:

1. the cup goes to ``(x, y)`` with heading ``yaw``; it rises ``rise`` metres from its height, or with ``seek > 0``
   comes down from above until it touches: its tip the highest surface under ``(x, y)``, or, while it holds an
   object, that object's lowest box the top of a box under it or the table (:mod:`.geometry`). This is Ravens'
   "descend until contact", found exactly instead of in 1 mm steps;
2. a held object moves with the cup, rigidly: its pose is the cup's composed with the grasp, at rest;
3. ``suction > 0`` grasps the movable object the tip touches (within :data:`TOUCH`), if the cup holds none:
   the weld equality between the cup and that object turns on (``mjx.Data.eq_active``) with its relative pose,
   the grasp, set to their relative pose now (Ravens' suction creates a fixed constraint at the pose of contact);
   ``suction <= 0`` releases it (the weld turns off);
4. the physics steps: the weld holds a grasped object to the cup against gravity and contacts, released objects
   fall and settle. The weld's relative pose lives in the model (``eq_data``), so each step writes the arena's
   grasp there (a model per arena under ``vmap``).

MuJoCo's adhesion actuator, the usual suction model, needs a body transmission, which MJX does not have; a weld
switched per arena does the same job.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.raven import geometry, poses
from jarena.arenas.raven.heightmap import BOUNDS
from jarena.arenas.raven.scene import Scene
from jarena.core import faults
from jarena.core.dynamics import Dynamics
from jarena.core.spec import Box
from jarena.core.tree import as_float32

if TYPE_CHECKING:
    from mujoco import mjx

CONTROL_FIELDS = ("x", "y", "yaw", "rise", "suction", "seek")
"""The cup's control, in order: target ``x``, ``y`` (metres, clipped to the workspace), heading ``yaw`` (radians),
``rise`` (metres up from the cup's height, clipped to [0, 1]), ``suction`` (on where > 0) and ``seek`` (come down
until contact where > 0)."""
TOUCH = 1e-3
"""The cup's tip touches a surface within this distance, metres."""
STILL = 5e-3
"""Objects are at rest when every movable one moves slower than this, metres per second (Ravens' ``is_static``)."""


@struct.dataclass
class RavenPhysics:
    """The physics state of a tabletop.

    Attributes:
      data: the ``mjx.Data``; after every step its kinematics (``geom_xpos``, ``xpos``...) match ``qpos``.
      held: int32 (): the held object's index in ``scene.movable``, -1 when the cup holds nothing.
      grasp: float32 (7,): the held object's pose in the cup's frame, position and quaternion ``(w, x, y, z)``.
      slip: float32 (): over the current (or last) grasp, the largest distance, metres, between the held object's
        origin and where the grasp puts it, after the physics steps of a control step: how well the weld holds.
      geom_size, geom_pos, geom_rgb: float32 (G, 3): the drawable boxes' half extents, centres in their body's
        frame (metres) and colours in [0, 1] (``scene.geom`` order): the scene's, or the episode's where a task
        changes them (a box of random size); sizes and positions go into the model at every step.
      geom_quat: float32 (G, 4): the boxes' orientations in their body's frame, the scene's or the episode's
        (assembling-kits' shapes); into the model with the sizes.
      scene: the scene (static).
      queue: what a task keeps of the episode beside the physics (palletizing's boxes still to come,
        :class:`.tasks.SpawnQueue`; packing's container and targets, :class:`.packing.Packing`; assembling-kits'
        shapes and slots, :class:`.kits.Kitting`); ``()`` for most tasks.
    """

    data: mjx.Data
    held: jax.Array
    grasp: jax.Array
    slip: jax.Array
    geom_size: jax.Array
    geom_pos: jax.Array
    geom_rgb: jax.Array
    geom_quat: jax.Array
    scene: Scene = struct.field(pytree_node=False)
    queue: Any = ()


def object_poses(physics: RavenPhysics) -> tuple[jax.Array, jax.Array]:
    """Every object's pose, ``(pos, quat)`` of shapes (N, 3) and (N, 4) in the scene's order: the free joints' of
    movable objects, the mocap poses of fixed ones."""
    scene, data = physics.scene, physics.data
    pos, quat = [], []
    for i, item in enumerate(scene.items):
        if item.shape.fixed:
            pos.append(data.mocap_pos[scene.mocap[i]])
            quat.append(data.mocap_quat[scene.mocap[i]])
        else:
            start = int(scene.qpos_address[scene.movable_slot[i]])
            pos.append(data.qpos[start:start + 3])
            quat.append(data.qpos[start + 3:start + 7])
    return jnp.stack(pos), jnp.stack(quat)


def place_objects(physics: RavenPhysics, pos: jax.Array, quat: jax.Array) -> RavenPhysics:
    """``physics`` with every object at rest at ``pos`` (N, 3) and ``quat`` (N, 4) (scene order); kinematics are
    left to the dynamics' ``after_reset``."""
    scene, data = physics.scene, physics.data
    qpos, qvel = data.qpos, data.qvel
    mocap_pos, mocap_quat = data.mocap_pos, data.mocap_quat
    for i, item in enumerate(scene.items):
        if item.shape.fixed:
            mocap_pos = mocap_pos.at[scene.mocap[i]].set(pos[i])
            mocap_quat = mocap_quat.at[scene.mocap[i]].set(quat[i])
        else:
            slot = scene.movable_slot[i]
            start, dof = int(scene.qpos_address[slot]), int(scene.qvel_address[slot])
            qpos = qpos.at[start:start + 7].set(jnp.concatenate([pos[i], quat[i]]))
            qvel = qvel.at[dof:dof + 6].set(0.0)
    return physics.replace(data=data.replace(qpos=qpos, qvel=qvel, mocap_pos=mocap_pos, mocap_quat=mocap_quat))


def place_movable(physics: RavenPhysics, slot: jax.Array, pos: jax.Array, quat: jax.Array,
                  where: jax.Array = True) -> RavenPhysics:
    """``physics`` with the movable object ``slot`` (int32 (), its index in ``scene.movable``; may be traced) at
    rest at ``pos`` (3,), ``quat`` (4,) where ``where`` holds; the others as they are. Kinematics are left to the
    next physics step."""
    scene, data = physics.scene, physics.data
    start, dof = jnp.asarray(scene.qpos_address)[slot], jnp.asarray(scene.qvel_address)[slot]
    pose = jnp.concatenate([jnp.asarray(pos, data.qpos.dtype), jnp.asarray(quat, data.qpos.dtype)])
    qpos = jnp.where(where, jax.lax.dynamic_update_slice(data.qpos, pose, (start,)), data.qpos)
    qvel = jnp.where(where, jax.lax.dynamic_update_slice(data.qvel, jnp.zeros(6, data.qvel.dtype), (dof,)),
                     data.qvel)
    return physics.replace(data=data.replace(qpos=qpos, qvel=qvel))


def cup_pose(physics: RavenPhysics) -> tuple[jax.Array, jax.Array]:
    """The cup's tip pose ``(pos (3,), quat (4,))``."""
    return physics.data.mocap_pos[physics.scene.cup], physics.data.mocap_quat[physics.scene.cup]


def control_spec() -> Box:
    """The cup's control (:data:`CONTROL_FIELDS`)."""
    return Box(np.array([BOUNDS[0][0], BOUNDS[1][0], -np.pi, 0.0, -1.0, -1.0], np.float32),
               np.array([BOUNDS[0][1], BOUNDS[1][1], np.pi, 1.0, 1.0, 1.0], np.float32))


def boxes(physics: RavenPhysics) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The drawable boxes where they are: ``(pos (G, 3), mat (G, 3, 3), half extents (G, 3))``."""
    geoms = jnp.asarray(physics.scene.geom)
    data = physics.data
    return data.geom_xpos[geoms], data.geom_xmat[geoms].reshape(-1, 3, 3), physics.geom_size


def at_rest(physics: RavenPhysics) -> jax.Array:
    """bool (): whether the cup holds nothing and every movable object moves slower than :data:`STILL`."""
    scene = physics.scene
    if scene.movable.size == 0:
        return physics.held < 0
    dof = jnp.asarray(scene.qvel_address)[:, None] + jnp.arange(3)
    speed = jnp.linalg.norm(physics.data.qvel[dof], axis=-1)
    return (physics.held < 0) & jnp.all(speed < STILL)


def _lowered(scene: Scene, physics: RavenPhysics, boxes, cup_xy: jax.Array, cup_quat: jax.Array,
             held_object: jax.Array) -> jax.Array:
    """The cup's height where the held object, carried over ``cup_xy`` with the cup at ``cup_quat``, comes to rest."""
    pos, mat, size = boxes
    obj_pos, obj_quat = object_poses(physics)
    body = jnp.asarray(scene.geom_object)
    # each box's pose in its object's frame, then in the held object's frame as carried (cup at height 0)
    inverse = poses.quat_conj(obj_quat[body])
    local_pos = poses.rotate(inverse, pos - obj_pos[body])
    local_rot = jax.vmap(lambda q, m: _matrix(q) @ m)(inverse, mat)
    carried_pos, carried_quat = poses.compose(jnp.concatenate([cup_xy, jnp.zeros(1)]), cup_quat,
                                              physics.grasp[:3], physics.grasp[3:])
    held_pos = carried_pos + poses.rotate(carried_quat, local_pos)
    held_mat = jax.vmap(lambda m: _matrix(carried_quat) @ m)(local_rot)
    mine = body == held_object
    solid = jnp.asarray(scene.geom_solid)
    return geometry.landing_height((held_pos, held_mat, size), boxes, ~mine & solid, mine & solid)


def _matrix(q: jax.Array) -> jax.Array:
    """The rotation matrix (3, 3) of a unit quaternion."""
    return jnp.stack([poses.rotate(q, e) for e in jnp.eye(3, dtype=q.dtype)], axis=-1)


def move_cup(physics: RavenPhysics, control: jax.Array) -> RavenPhysics:
    """Steps 1-3 of a control step (the cup moves, a held object with it, suction grasps or releases), no physics."""
    scene, data = physics.scene, physics.data
    control = jnp.asarray(control, jnp.float32)
    xy = jnp.clip(control[:2], jnp.asarray([BOUNDS[0][0], BOUNDS[1][0]]), jnp.asarray([BOUNDS[0][1], BOUNDS[1][1]]))
    quat = poses.yaw_quat(control[2])
    rise, suction, seek = jnp.clip(control[3], 0.0, 1.0), control[4] > 0, control[5] > 0
    holding = physics.held >= 0
    movable = jnp.asarray(scene.movable)
    held_object = jnp.where(holding, movable[jnp.maximum(physics.held, 0)], -1)
    every_box = boxes(physics)
    others = jnp.asarray(scene.geom_object) != held_object
    surface, box = geometry.cast_down(xy[None], *every_box, others)
    surface, box = surface[0], box[0]
    landing = _lowered(scene, physics, every_box, xy, quat, held_object)
    old_pos, _ = cup_pose(physics)
    z = jnp.where(seek, jnp.where(holding, landing, surface), old_pos[2] + rise)
    pos = jnp.concatenate([xy, z[None]])

    # a held object moves with the cup, at rest
    slot = jnp.maximum(physics.held, 0)
    start, dof = jnp.asarray(scene.qpos_address)[slot], jnp.asarray(scene.qvel_address)[slot]
    carried = jnp.concatenate(poses.compose(pos, quat, physics.grasp[:3], physics.grasp[3:]))
    qpos = jnp.where(holding, jax.lax.dynamic_update_slice(data.qpos, carried, (start,)), data.qpos)
    qvel = jnp.where(holding, jax.lax.dynamic_update_slice(data.qvel, jnp.zeros(6), (dof,)), data.qvel)

    # suction: grasp the movable object the tip touches, or let go
    touched = jnp.where(box >= 0, jnp.asarray(scene.geom_object)[box], -1)
    touched_slot = jnp.where(touched >= 0, jnp.asarray(scene.movable_slot)[touched], -1)
    grasp = suction & ~holding & (z - surface <= TOUCH) & (touched_slot >= 0)
    held = jnp.where(grasp, touched_slot, jnp.where(suction, physics.held, -1))
    start = jnp.asarray(scene.qpos_address)[jnp.maximum(touched_slot, 0)]
    touched_pose = jax.lax.dynamic_slice(qpos, (start,), (7,))
    relative = jnp.concatenate(poses.relative(pos, quat, touched_pose[:3], touched_pose[3:]))
    grasp_pose = jnp.where(grasp, relative, physics.grasp)

    data = data.replace(qpos=qpos, qvel=qvel, mocap_pos=data.mocap_pos.at[scene.cup].set(pos),
                        mocap_quat=data.mocap_quat.at[scene.cup].set(quat),
                        eq_active=(jnp.arange(scene.movable.size) == held).astype(data.eq_active.dtype))
    return physics.replace(data=data, held=held.astype(jnp.int32), grasp=grasp_pose,
                           slip=jnp.where(grasp, 0.0, physics.slip))


def grasp_error(physics: RavenPhysics) -> jax.Array:
    """float32 (): the distance, metres, between the held object's origin and where the grasp puts it (0 when the
    cup holds nothing)."""
    scene = physics.scene
    cup, quat = cup_pose(physics)
    start = jnp.asarray(scene.qpos_address)[jnp.maximum(physics.held, 0)]
    actual = jax.lax.dynamic_slice(physics.data.qpos, (start,), (3,))
    expected, _ = poses.compose(cup, quat, physics.grasp[:3], physics.grasp[3:])
    return jnp.where(physics.held >= 0, jnp.linalg.norm(actual - expected), 0.0)


def _with_grasp(model: mjx.Model, grasp: jax.Array) -> mjx.Model:
    """``model`` whose welds hold their object at ``grasp`` (7,) in the cup's frame (anchor at the object's origin)."""
    if model.neq == 0:
        return model
    data = model.eq_data.at[:, 0:3].set(0.0).at[:, 3:10].set(grasp).at[:, 10].set(1.0)
    return model.replace(eq_data=data)


def _with_shapes(model: mjx.Model, physics: RavenPhysics) -> mjx.Model:
    """``model`` with the episode's box sizes, positions and orientations, and the bounding spheres that go with
    them (only where the scene has resizable shapes); masses and inertias stay the model's."""
    scene = physics.scene
    if not scene.resizable:
        return model
    geoms = jnp.asarray(scene.geom)
    return model.replace(geom_size=model.geom_size.at[geoms].set(physics.geom_size),
                         geom_pos=model.geom_pos.at[geoms].set(physics.geom_pos),
                         geom_quat=model.geom_quat.at[geoms].set(physics.geom_quat),
                         geom_rbound=model.geom_rbound.at[geoms].set(jnp.linalg.norm(physics.geom_size, axis=-1)))


def raven_dynamics(scene: Scene, substeps: int = 4, render: Callable | None = None) -> Dynamics:
    """The :class:`Dynamics` of ``scene``: a control step is :func:`move_cup`, then ``substeps`` MJX steps.

    Params are :class:`jarena.arenas.mjx.MjxParams` (mass and friction scales). ``init`` parks every object off
    the table (a task's ``initialize`` places them) with the cup above the workspace. ``render`` draws host
    frames for videos.
    """
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    from mujoco import mjx  # imported when a Raven arena is built, so that importing jarena does not load MuJoCo

    from jarena.arenas.mjx.dynamics import MjxParams, apply_params, while_line_search

    with jax.ensure_compile_time_eval():
        device_model = mjx.put_model(scene.model)

    def init(key, params):
        data = mjx.make_data(device_model)
        return RavenPhysics(data=data, held=jnp.asarray(-1, jnp.int32),
                            grasp=jnp.asarray([0, 0, 0, 1, 0, 0, 0], jnp.float32), slip=jnp.zeros((), jnp.float32),
                            geom_size=jnp.asarray(scene.geom_size), geom_pos=jnp.asarray(scene.geom_pos),
                            geom_rgb=jnp.asarray(scene.geom_rgb), geom_quat=jnp.asarray(scene.geom_quat),
                            scene=scene)

    def after_reset(physics, params):
        model = _with_shapes(apply_params(device_model, params), physics)
        return physics.replace(data=mjx.kinematics(model, physics.data))

    def step(physics, control, params):
        physics = move_cup(physics, control)
        model = _with_grasp(_with_shapes(apply_params(device_model, params), physics), physics.grasp)
        with while_line_search():  # MJX's states or within rounding, sooner (jarena.arenas.mjx.dynamics)
            data = jax.lax.fori_loop(0, substeps, lambda _, d: mjx.step(model, d), physics.data)
        physics = physics.replace(data=mjx.kinematics(model, data))
        return physics.replace(slip=jnp.maximum(physics.slip, grasp_error(physics)))

    return Dynamics(init=init, step=step, control_spec=control_spec(),
                    default_params=lambda: as_float32(MjxParams()),
                    timestep=float(scene.model.opt.timestep) * substeps, name="raven", after_reset=after_reset,
                    render=render,
                    finite=lambda p: faults.all_finite((p.data.qpos, p.data.qvel, p.grasp)))
