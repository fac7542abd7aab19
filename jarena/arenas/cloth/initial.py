"""Initial cloth states, generated on device from the episode's key (as every jarena episode).

- ``flat``: the flat cloth at a random rotation about z, face up or face down (probability 1/2, SoftGym's
  ``flip_face``), shifted by up to ``FLAT_SHIFT`` metres; always inside the camera's view.
- ``crumpled``: SoftGym's procedure, simulated with the cloth's own physics: from a flat cloth (random
  rotation and face), twice, a picker grasps a random particle, lifts it by U(0.05, 0.4) m, sways it by
  U(-0.15, 0.15) m in x and y, drops it and lets it settle (SoftGym lifts once, without the sway);
  then with probability 0.7 drags another random particle by U(-0.3, 0.3) m in x and y at
  0.1 m height and lets go; finally the cloth is moved (x-y only) so that its mean is within
  ``CRUMPLED_SHIFT`` of the origin. About 250 physics steps, inside ``reset``.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from jarena.arenas.cloth import collision
from jarena.arenas.cloth.physics import READY_HEIGHT, ClothParams, ClothPhysics, ClothState

FLAT_SHIFT = 0.1
CRUMPLED_SHIFT = 0.05


def _flat_positions(key: jax.Array, physics: ClothPhysics, params: ClothParams, shift: float) -> jax.Array:
    """float32 (N, 3): the rest grid rotated, maybe flipped face down, shifted, resting on the floor."""
    k_angle, k_flip, k_shift = jax.random.split(key, 3)
    rest = jnp.asarray(physics.mesh.rest_positions)
    flip = jax.random.bernoulli(k_flip)
    xy = rest[:, :2] * jnp.where(flip, jnp.array([1.0, -1.0]), jnp.array([1.0, 1.0]))  # mirrored: back face up
    angle = jax.random.uniform(k_angle, (), jnp.float32, 0.0, 2 * math.pi)
    c, s = jnp.cos(angle), jnp.sin(angle)
    xy = jnp.stack([xy[:, 0] * c - xy[:, 1] * s, xy[:, 0] * s + xy[:, 1] * c], -1)
    xy = xy + jax.random.uniform(k_shift, (2,), jnp.float32, -shift, shift)
    z = jnp.full((xy.shape[0], 1), params.particle_radius)
    return jnp.concatenate([xy, z], -1).astype(jnp.float32)


def flat(key: jax.Array, physics: ClothPhysics, params: ClothParams) -> ClothState:
    """A flat cloth at rest (see the module docstring)."""
    return physics.state_from_positions(_flat_positions(key, physics, params, FLAT_SHIFT))


def _controls(k: int, picker: int, segments) -> jax.Array:
    """Stacks ``(delta (3,), grip, steps)`` segments for picker ``picker`` (the others stay open and still)."""
    out = []
    for delta, grip, steps in segments:
        control = jnp.zeros((k, 4), jnp.float32).at[:, 3].set(-1.0)
        control = control.at[picker].set(jnp.concatenate([jnp.asarray(delta, jnp.float32).reshape(3),
                                                           jnp.asarray(grip, jnp.float32).reshape(1)]))
        out.append(jnp.broadcast_to(control, (steps, k, 4)))
    return jnp.concatenate(out)


def _simulate(physics: ClothPhysics, params: ClothParams, state: ClothState, controls: jax.Array) -> ClothState:
    return jax.lax.scan(lambda s, c: (physics.step(s, c, params), None), state, controls)[0]


def _grab_and_move(physics, params, state, particle, rise, shift, hold, settle, lift_steps, move_steps, enabled):
    """Picker 0 grasps ``particle``, rises ``rise`` m, moves ``shift`` (x, y) m, holds, lets go, returns, settles."""
    k = int(physics.num_pickers)
    target = state.positions[particle]
    grip = jnp.where(enabled, 1.0, -1.0)
    ready = jnp.array([0.0, 0.0, READY_HEIGHT])
    zero = jnp.zeros(3)
    segments = [
        (target - state.picker_positions[0], -1.0, 1),
        (zero, grip, 1),
        (jnp.array([0.0, 0.0, rise]) / lift_steps, grip, lift_steps),
        (jnp.concatenate([shift, jnp.zeros(1)]) / move_steps, grip, move_steps),
        (zero, grip, hold),
        (zero, -1.0, 1),
        (ready - (target + jnp.concatenate([shift, jnp.array([rise])])), -1.0, 1),
        (zero, -1.0, settle),
    ]
    return _simulate(physics, params, state, _controls(k, 0, segments))


def crumpled(key: jax.Array, physics: ClothPhysics, params: ClothParams) -> ClothState:
    """A crumpled cloth (see the module docstring)."""
    k_flat, k_lift, k_height, k_drag, k_do, k_shift, k_centre = jax.random.split(key, 7)
    n = physics.mesh.num_particles
    state = physics.state_from_positions(_flat_positions(k_flat, physics, params, 0.0))
    for k_particle, k_rise, k_sway in jax.random.split(k_lift, (2, 3)):
        height = jax.random.uniform(k_rise, (), jnp.float32, 0.05, 0.4)
        sway = jax.random.uniform(k_sway, (2,), jnp.float32, -0.15, 0.15)
        state = _grab_and_move(physics, params, state, jax.random.randint(k_particle, (), 0, n), height, sway,
                               hold=5, settle=40, lift_steps=20, move_steps=10, enabled=jnp.array(True))
    shift = jax.random.uniform(k_shift, (2,), jnp.float32, -0.3, 0.3)
    state = _grab_and_move(physics, params, state, jax.random.randint(k_drag, (), 0, n), 0.1, shift,
                           hold=5, settle=60, lift_steps=5, move_steps=15, enabled=jax.random.bernoulli(k_do, 0.7))
    centre = jax.random.uniform(k_centre, (2,), jnp.float32, -CRUMPLED_SHIFT, CRUMPLED_SHIFT)
    offset = centre - collision.fixed_sum(state.positions[:, :2], axis=0) / n
    positions = state.positions.at[:, :2].add(offset)
    return state.replace(positions=positions, velocities=jnp.zeros_like(positions))


INITIAL_STATES = {"flat": flat, "crumpled": crumpled}
"""Name -> ``(key, physics, params) -> ClothState``; the ``initial:`` option of cloth arena strings."""
