"""PushT's planar physics in pure JAX: a PD-driven kinematic disc pushes a T block inside four walls.

The facts are those of Diffusion Policy's ``pusht_env`` (pymunk, Chipmunk's solver), and one physics step does
what ``pusht_env``'s loop and ``pymunk.Space.step`` do, in the same order:

1. the pusher's PD law towards the target: ``v += (k_p (target - p) - k_v v) dt`` (the disc is kinematic:
   nothing pushes it back, and it passes through the walls);
2. positions: ``p += v dt`` for the pusher; the block's centre of gravity and angle move by its velocity plus the
   bias velocity of the last step's overlap correction;
3. contacts at the new positions: the disc against each of the T's two boxes (the closest points, or the face
   of least overlap when the disc's centre is inside), and the six corners of the T's hull against the walls'
   inner faces (``wall_low`` and ``wall_high``: segments at 5 and 506 of radius 2);
4. the block's velocity is multiplied by ``damping ** dt``: pymunk's ``damping`` is the fraction of velocity
   *kept* per second, and ``pusht_env`` sets it to 0, so the block keeps no momentum from one step to the next
   and moves only while it is pushed (quasi-static);
5. Chipmunk's sequential impulses, ``iterations`` passes over the contacts (the disc's first, then the walls'; in
   pymunk the order varies from step to step, which matters only where several contacts fight, as when the disc
   squeezes the block against a wall): a normal impulse ``>= 0`` per contact that cancels the approach velocity
   (no bounce), warm-started from the last step's impulse where the contact persists, and a separate bias impulse
   that pushes an overlap deeper than ``slop`` out by the fraction ``1 - bias ** dt`` per step (Chipmunk's
   ``collision_bias``, the overlap left after a second).

``pusht_env`` sets ``friction = 1`` on the bodies, where pymunk ignores it (friction belongs to shapes, whose
default is 0): its contacts are frictionless, and so are these. The walls are half-planes: a block squeezed
through one by the disc is pushed back in, where pymunk's thin segments may let it pass.

The state keeps the pose ``pusht_env`` reports, the block's body origin and angle (:func:`block_pose`); the
velocities are those of the centre of gravity, about which the block turns, as in pymunk.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.pusht import geometry

NUM_PUSHER_CONTACTS = len(geometry.BOXES)  # the disc against each box
NUM_WALL_CONTACTS = 2 * len(geometry.HULL)  # each hull corner against the nearer wall of each axis
NUM_CONTACTS = NUM_PUSHER_CONTACTS + NUM_WALL_CONTACTS


@struct.dataclass
class PushTParams:
    """Physical constants (vmap over them to vary arenas); units of the 512 x 512 plane and seconds.

    Attributes:
      dt: seconds per physics step (``pusht_env``: 100 Hz).
      k_p, k_v: the pusher's PD gains.
      pusher_radius: the disc's radius.
      block_mass, block_inertia: the T's mass and moment of inertia about its centre of gravity.
      block_cog: float32 (2,), the T's centre of gravity in its body frame.
      damping: fraction of the block's velocity kept per second (pymunk's ``Space.damping``).
      wall_low, wall_high: the walls' inner faces along x and y.
      slop: overlap left uncorrected (pymunk's ``collision_slop``).
      bias: fraction of a deeper overlap left after one second (pymunk's ``collision_bias``, ``0.9 ** 60``).
      pusher_low, pusher_high: range of the pusher's initial x and y (uniform).
      block_low, block_high: range of the block's initial x and y (its body origin, uniform).
      angle_range: the block's initial angle is uniform in ``[-angle_range, angle_range)``.
    """

    dt: jax.Array = 0.01
    k_p: jax.Array = 100.0
    k_v: jax.Array = 20.0
    pusher_radius: jax.Array = 15.0
    block_mass: jax.Array = geometry.MASS
    block_inertia: jax.Array = geometry.INERTIA
    block_cog: jax.Array = struct.field(default_factory=lambda: jnp.asarray(geometry.CENTRE_OF_GRAVITY))
    damping: jax.Array = 0.0
    wall_low: jax.Array = 7.0
    wall_high: jax.Array = 504.0
    slop: jax.Array = 0.1
    bias: jax.Array = 0.9**60
    pusher_low: jax.Array = 50.0
    pusher_high: jax.Array = 450.0
    block_low: jax.Array = 100.0
    block_high: jax.Array = 400.0
    angle_range: jax.Array = jnp.pi


@struct.dataclass
class PushTState:
    """The scene's state (float32 leaves; the plane's units, radians, seconds).

    Attributes:
      pusher: (2,) the disc's centre.
      pusher_velocity: (2,).
      block: (2,) the T's body origin (see :mod:`.geometry`), the position ``pusht_env`` reports.
      block_angle: () radians, not wrapped.
      block_velocity: (2,) of the centre of gravity; block_spin: () radians per second about it.
      bias_velocity: (2,), bias_spin: (): the overlap correction, applied in the next step's position update.
      impulses: (NUM_CONTACTS,) each contact's normal impulse in the last step (0 where it did not touch), which
        warm-starts the next step's solver.
    """

    pusher: jax.Array
    pusher_velocity: jax.Array
    block: jax.Array
    block_angle: jax.Array
    block_velocity: jax.Array
    block_spin: jax.Array
    bias_velocity: jax.Array
    bias_spin: jax.Array
    impulses: jax.Array


def block_pose(state: PushTState) -> jax.Array:
    """float32 (3,): the block's ``(x, y, angle)`` as ``pusht_env`` reports it: its body origin and its angle."""
    return jnp.concatenate([state.block, state.block_angle[None]]).astype(jnp.float32)


def place(pusher: jax.Array, pose: jax.Array, params: PushTParams) -> PushTState:
    """The scene at rest with the pusher at ``pusher`` (2,) and the block at ``pose`` (3,) (body origin, angle)."""
    pose = jnp.asarray(pose, jnp.float32)
    zero2, zero = jnp.zeros((2,), jnp.float32), jnp.zeros((), jnp.float32)
    return PushTState(pusher=jnp.asarray(pusher, jnp.float32), pusher_velocity=zero2,
                      block=pose[:2], block_angle=pose[2],
                      block_velocity=zero2, block_spin=zero, bias_velocity=zero2, bias_spin=zero,
                      impulses=jnp.zeros((NUM_CONTACTS,), jnp.float32))


# numpy, not jnp: a jnp constant would start JAX's backend at import, before a multi-process run can join
_FACE_NORMALS = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]], np.float32)


def _pusher_contacts(pusher, centre, rot, params):
    """The disc against each box: (arms (2, 2): the contact point on the T relative to its centre of gravity,
    normals (2, 2): the direction the T is pushed, separations (2,): < 0 where they overlap)."""
    boxes = jnp.asarray(geometry.BOXES)
    low, high = boxes[:, 0::2], boxes[:, 1::2]  # (2, 2) each: (x, y) per box
    local = rot.T @ (pusher - centre) + params.block_cog  # the disc's centre in the body frame
    closest = jnp.clip(local, low, high)
    delta = local - closest
    squared = jnp.sum(delta * delta, -1)
    outside = squared > 0
    distance = jnp.sqrt(jnp.where(outside, squared, 1.0))
    # a centre inside a box leaves by the face of least depth
    depths = jnp.concatenate([local - low, high - local], -1)[:, jnp.array([0, 2, 1, 3])]  # x0, x1, y0, y1
    depth = jnp.min(depths, -1)
    face_normal = jnp.asarray(_FACE_NORMALS)[jnp.argmin(depths, -1)]
    normal = jnp.where(outside[:, None], delta / distance[:, None], face_normal)  # from the box to the disc
    point = jnp.where(outside[:, None], closest, local + depth[:, None] * face_normal)
    separation = jnp.where(outside, distance, -depth) - params.pusher_radius
    return (point - params.block_cog) @ rot.T, -normal @ rot.T, separation


def _wall_contacts(centre, rot, params):
    """Each hull corner against the nearer wall of each axis, corner-major: arms (12, 2), normals (12, 2),
    separations (12,)."""
    arms = (jnp.asarray(geometry.HULL) - params.block_cog) @ rot.T  # (6, 2)
    corners = centre + arms
    near_low = corners < 0.5 * (params.wall_low + params.wall_high)
    separation = jnp.where(near_low, corners - params.wall_low, params.wall_high - corners)  # (6, 2)
    normal = jnp.where(near_low, 1.0, -1.0)[:, :, None] * jnp.eye(2, dtype=jnp.float32)  # (6, axis, 2)
    return jnp.repeat(arms, 2, axis=0), normal.reshape(-1, 2), separation.reshape(-1)


def physics_step(state: PushTState, target: jax.Array, params: PushTParams, iterations: int = 10) -> PushTState:
    """One physics step of ``params.dt`` seconds towards ``target`` (2,), clipped to the plane (module docstring)."""
    dt = params.dt
    target = jnp.clip(jnp.asarray(target, jnp.float32), 0.0, geometry.SIZE)
    pusher_velocity = state.pusher_velocity + (params.k_p * (target - state.pusher)
                                               - params.k_v * state.pusher_velocity) * dt
    pusher = state.pusher + pusher_velocity * dt
    centre = state.block + geometry.rotation(state.block_angle) @ params.block_cog
    centre = centre + (state.block_velocity + state.bias_velocity) * dt
    angle = state.block_angle + (state.block_spin + state.bias_spin) * dt
    rot = geometry.rotation(angle)

    pushed, walls = _pusher_contacts(pusher, centre, rot, params), _wall_contacts(centre, rot, params)
    arms, normals, separation = (jnp.concatenate(pair) for pair in zip(pushed, walls, strict=True))
    touching = separation <= 0
    turn = arms[:, 0] * normals[:, 1] - arms[:, 1] * normals[:, 0]  # r x n
    inv_mass, inv_inertia = 1.0 / params.block_mass, 1.0 / params.block_inertia
    # Per contact: the direction (n, r x n) an impulse acts along, its normal mass (0 where the contact does not
    # touch, which then takes no impulse), the velocity its point must not approach along the normal (the
    # pusher's, or a wall's: 0), the bias velocity that corrects its overlap, and its warm start (the impulse of
    # the last step where the contact still touches).
    directions = jnp.stack([normals[:, 0], normals[:, 1], turn], -1)  # (C, 3)
    gains = directions * jnp.stack([inv_mass, inv_mass, inv_inertia])
    masses = jnp.where(touching, 1.0 / (inv_mass + inv_inertia * turn * turn), 0.0)
    approaches = jnp.concatenate([normals[:NUM_PUSHER_CONTACTS] @ pusher_velocity,
                                  jnp.zeros((NUM_WALL_CONTACTS,), jnp.float32)])
    bias_targets = -(1.0 - params.bias**dt) * jnp.minimum(0.0, separation + params.slop) / dt
    warm = jnp.where(touching, state.impulses, 0.0)
    kept = params.damping**dt
    velocity = jnp.concatenate([state.block_velocity, state.block_spin[None]]) * kept + warm @ gains  # (3,)

    # Gauss-Seidel, one contact per trip of a rolled loop (contact k % C sees the impulses of those before it):
    # unrolled over the contacts, XLA duplicates the chain of scalar updates into every value it feeds, and the
    # step compiled three times slower and ran slower on a CPU.
    def update(k, carry):
        velocity, bias, impulses, biases = carry
        c = k % NUM_CONTACTS
        direction, gain, mass = directions[c], gains[c], masses[c]
        new_bias = jnp.maximum(biases[c] + (bias_targets[c] - bias @ direction) * mass, 0.0)
        new_impulse = jnp.maximum(impulses[c] - (velocity @ direction - approaches[c]) * mass, 0.0)
        bias = bias + (new_bias - biases[c]) * gain
        velocity = velocity + (new_impulse - impulses[c]) * gain
        return velocity, bias, impulses.at[c].set(new_impulse), biases.at[c].set(new_bias)

    velocity, bias, impulses, _ = jax.lax.fori_loop(
        0, iterations * NUM_CONTACTS, update, (velocity, jnp.zeros((3,), jnp.float32), warm, jnp.zeros_like(warm)))
    return PushTState(pusher=pusher, pusher_velocity=pusher_velocity, block=centre - rot @ params.block_cog,
                      block_angle=angle, block_velocity=velocity[:2], block_spin=velocity[2],
                      bias_velocity=bias[:2], bias_spin=bias[2], impulses=impulses)


def step(state: PushTState, target: jax.Array, params: PushTParams, substeps: int = 10,
         iterations: int = 10) -> PushTState:
    """``substeps`` physics steps towards ``target`` (2,): one control step (``pusht_env``: 10 Hz)."""
    return jax.lax.fori_loop(0, substeps, lambda _, s: physics_step(s, target, params, iterations), state)


def init(key: jax.Array, params: PushTParams) -> PushTState:
    """A random scene at rest, as ``pusht_env.reset`` draws it (uniform ranges of :class:`PushTParams`).

    ``pusht_env`` then runs one physics step with the pusher at rest, whose only effect is the bias velocity of
    an overlap between the shapes, applied a step later; it is left out here (a reset then compiles without the
    contact solver), so a start with overlapping shapes separates them one physics step later.
    """
    k_pusher, k_block, k_angle = jax.random.split(key, 3)
    pusher = jax.random.uniform(k_pusher, (2,), jnp.float32, params.pusher_low, params.pusher_high)
    origin = jax.random.uniform(k_block, (2,), jnp.float32, params.block_low, params.block_high)
    angle = jax.random.uniform(k_angle, (), jnp.float32, -params.angle_range, params.angle_range)
    return place(pusher, jnp.concatenate([origin, angle[None]]), params)
