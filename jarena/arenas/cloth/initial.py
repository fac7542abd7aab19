"""Initial cloth states, generated on device from the episode's key (as every jarena episode).

- ``flat``: the flat cloth at a random rotation about z, face up or face down (probability 1/2, SoftGym's
  ``flip_face``), shifted by up to ``FLAT_SHIFT`` metres; always inside the camera's view.
- ``crumpled``: SoftGym's procedure, simulated with the cloth's own physics: from a flat cloth (random
  rotation and face), twice, a picker grasps a random particle, lifts it by U(0.05, 0.4) m, sways it by
  U(-0.15, 0.15) m in x and y, drops it and lets it settle (SoftGym lifts once, without the sway);
  then with probability 0.7 drags another random particle by U(-0.3, 0.3) m in x and y at
  0.1 m height and lets go; finally the cloth is moved (x-y only) so that its mean is within
  ``CRUMPLED_SHIFT`` of the origin. About 250 physics steps, inside ``reset``, as one scan (one copy of the
  physics step in the compiled program, about half the code of a scan per move, the same states to the bit).
"""

from __future__ import annotations

import functools
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


SEGMENTS = 8
"""The segments of a grab-and-move (see :func:`_grab_and_move_control`): go to the particle, grasp, rise, move,
hold, let go, return to the ready pose, settle."""


def _grab_and_move_control(k: int, segment: jax.Array, state: ClothState, target: jax.Array, move: dict
                           ) -> jax.Array:
    """float32 (K, 4): the control of one step in ``segment`` (int32 scalar, in ``[0, SEGMENTS)``) of a
    grab-and-move by picker 0 (the others stay open and still): go from where the picker is to ``target`` (3,),
    grasp (``move["grip"]`` > 0; a disabled grab keeps the picker open), rise by ``move["lift"]`` (3,) per step,
    move by ``move["move"]`` (3,) per step, hold, let go, return to the ready pose from ``target +
    move["offset"]`` (3,), settle."""
    zero = jnp.zeros(3)
    back = jnp.array([0.0, 0.0, READY_HEIGHT]) - (target + move["offset"])
    deltas = jnp.stack([target - state.picker_positions[0], zero, move["lift"], move["move"], zero, zero, back, zero])
    grip = move["grip"]
    grips = jnp.stack([-1.0, grip, grip, grip, grip, -1.0, -1.0, -1.0]).astype(jnp.float32)
    mine = jnp.concatenate([deltas[segment].astype(jnp.float32), grips[segment][None]])
    return jnp.zeros((k, 4), jnp.float32).at[:, 3].set(-1.0).at[0].set(mine)


def _grab_and_move_all(physics: ClothPhysics, params: ClothParams, state: ClothState, moves: list[dict]
                       ) -> ClothState:
    """Runs the grab-and-moves ``moves`` one after the other in one scan of the physics (one copy of the step in
    the compiled program, however many moves).

    Each move: ``particle`` (int32), ``rise``, ``shift`` (2,), ``enabled`` (bool) traced; ``hold``, ``settle``,
    ``lift_steps``, ``move_steps`` static ints. The picker goes to where the particle lies when its move starts,
    rises ``rise`` m over ``lift_steps`` steps, moves ``shift`` (x, y) m over ``move_steps``, holds ``hold``
    steps, lets go, returns to the ready pose and settles ``settle`` steps.
    """
    k = int(physics.num_pickers)
    move_of, segment_of, table = [], [], []
    for m, move in enumerate(moves):
        lengths = (1, 1, move["lift_steps"], move["move_steps"], move["hold"], 1, 1, move["settle"])
        for segment, steps in enumerate(lengths):
            move_of += [m] * steps
            segment_of += [segment] * steps
        # per-step displacements divided by the static step counts, outside the loop
        table.append(dict(particle=move["particle"], grip=jnp.where(move["enabled"], 1.0, -1.0),
                          lift=jnp.array([0.0, 0.0, move["rise"]]) / move["lift_steps"],
                          move=jnp.concatenate([move["shift"], jnp.zeros(1)]) / move["move_steps"],
                          offset=jnp.concatenate([move["shift"], jnp.array([move["rise"]])])))
    table = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *table)

    def body(carry, schedule):
        state, target = carry
        m, segment = schedule
        move = jax.tree_util.tree_map(lambda x: x[m], table)
        target = jnp.where(segment == 0, state.positions[move["particle"]], target)
        control = _grab_and_move_control(k, segment, state, target, move)
        return (physics.step(state, control, params), target), None

    schedule = (jnp.asarray(move_of, jnp.int32), jnp.asarray(segment_of, jnp.int32))
    return jax.lax.scan(body, (state, jnp.zeros(3, jnp.float32)), schedule)[0][0]


@functools.partial(jax.jit, static_argnums=1)
def crumpled(key: jax.Array, physics: ClothPhysics, params: ClothParams) -> ClothState:
    """A crumpled cloth (see the module docstring).

    Compiled as one program whether it is called eagerly or inside a caller's ``jit`` (where it is inlined, to
    the same bits as without this ``jit``): its ~250 physics steps amplify the last-bit differences between
    op-by-op and fused arithmetic (in the random pose and heights before the scan) to centimetres, so an eager
    reset would otherwise start a different cloth from the jitted one. The params pass an optimization barrier:
    a caller's jit that holds them as constants would otherwise fold them at compile time, another last-bit
    difference (measured: 3-5 cm apart from the same episode id)."""
    params = jax.lax.optimization_barrier(params)
    k_flat, k_lift, k_height, k_drag, k_do, k_shift, k_centre = jax.random.split(key, 7)
    n = physics.mesh.num_particles
    state = physics.state_from_positions(_flat_positions(k_flat, physics, params, 0.0))
    moves = []
    for k_particle, k_rise, k_sway in jax.random.split(k_lift, (2, 3)):
        height = jax.random.uniform(k_rise, (), jnp.float32, 0.05, 0.4)
        sway = jax.random.uniform(k_sway, (2,), jnp.float32, -0.15, 0.15)
        moves.append(dict(particle=jax.random.randint(k_particle, (), 0, n), rise=height, shift=sway,
                          enabled=jnp.array(True), hold=5, settle=40, lift_steps=20, move_steps=10))
    shift = jax.random.uniform(k_shift, (2,), jnp.float32, -0.3, 0.3)
    moves.append(dict(particle=jax.random.randint(k_drag, (), 0, n), rise=0.1, shift=shift,
                      enabled=jax.random.bernoulli(k_do, 0.7), hold=5, settle=60, lift_steps=5, move_steps=15))
    state = _grab_and_move_all(physics, params, state, moves)
    centre = jax.random.uniform(k_centre, (2,), jnp.float32, -CRUMPLED_SHIFT, CRUMPLED_SHIFT)
    offset = centre - collision.fixed_sum(state.positions[:, :2], axis=0) / n
    positions = state.positions.at[:, :2].add(offset)
    return state.replace(positions=positions, velocities=jnp.zeros_like(positions))


INITIAL_STATES = {"flat": flat, "crumpled": crumpled}
"""Name -> ``(key, physics, params) -> ClothState``; the ``initial:`` option of cloth arena strings."""
