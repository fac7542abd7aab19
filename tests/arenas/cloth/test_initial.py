"""Initial cloth states: the crumpling procedure runs as one scan of the physics, step for step the three
separate simulations it describes (SoftGym's lift-and-drop twice, then a drag)."""

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.cloth import collision, initial
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.arenas.cloth.physics import READY_HEIGHT, ClothPhysics


def _reference_grab_and_move(physics, params, state, particle, rise, shift, hold, settle, lift_steps, move_steps,
                             enabled):
    """One grab-and-move as its own simulation: the controls of its segments laid out, then one scan."""
    k = int(physics.num_pickers)
    target = state.positions[particle]
    grip = jnp.where(enabled, 1.0, -1.0)
    zero = jnp.zeros(3)
    segments = [
        (target - state.picker_positions[0], -1.0, 1),
        (zero, grip, 1),
        (jnp.array([0.0, 0.0, rise]) / lift_steps, grip, lift_steps),
        (jnp.concatenate([shift, jnp.zeros(1)]) / move_steps, grip, move_steps),
        (zero, grip, hold),
        (zero, -1.0, 1),
        (jnp.array([0.0, 0.0, READY_HEIGHT]) - (target + jnp.concatenate([shift, jnp.array([rise])])), -1.0, 1),
        (zero, -1.0, settle),
    ]
    controls = []
    for delta, g, steps in segments:
        control = jnp.zeros((k, 4), jnp.float32).at[:, 3].set(-1.0)
        control = control.at[0].set(jnp.concatenate([jnp.asarray(delta, jnp.float32).reshape(3),
                                                     jnp.asarray(g, jnp.float32).reshape(1)]))
        controls.append(jnp.broadcast_to(control, (steps, k, 4)))
    return jax.lax.scan(lambda s, c: (physics.step(s, c, params), None), state, jnp.concatenate(controls))[0]


def _reference_crumpled(key, physics, params):
    k_flat, k_lift, k_height, k_drag, k_do, k_shift, k_centre = jax.random.split(key, 7)
    n = physics.mesh.num_particles
    state = physics.state_from_positions(initial._flat_positions(k_flat, physics, params, 0.0))
    for k_particle, k_rise, k_sway in jax.random.split(k_lift, (2, 3)):
        height = jax.random.uniform(k_rise, (), jnp.float32, 0.05, 0.4)
        sway = jax.random.uniform(k_sway, (2,), jnp.float32, -0.15, 0.15)
        state = _reference_grab_and_move(physics, params, state, jax.random.randint(k_particle, (), 0, n), height,
                                         sway, 5, 40, 20, 10, jnp.array(True))
    shift = jax.random.uniform(k_shift, (2,), jnp.float32, -0.3, 0.3)
    state = _reference_grab_and_move(physics, params, state, jax.random.randint(k_drag, (), 0, n), 0.1, shift, 5, 60,
                                     5, 15, jax.random.bernoulli(k_do, 0.7))
    centre = jax.random.uniform(k_centre, (2,), jnp.float32, -initial.CRUMPLED_SHIFT, initial.CRUMPLED_SHIFT)
    offset = centre - collision.fixed_sum(state.positions[:, :2], axis=0) / n
    return state.positions.at[:, :2].add(offset)


def test_crumpling_in_one_scan_is_the_three_simulations_to_the_bit():
    physics = ClothPhysics(ClothMesh(10, 10, 0.3 / 9), solver="xla")
    params = physics.default_params()
    keys = jax.random.split(jax.random.key(7), 8)  # among them, drags done and skipped (probability 0.7)
    # params as arguments: crumpled keeps them from being folded into constants, which the reference does not
    ours, reference = (jax.jit(jax.vmap(f, in_axes=(0, None))).lower(keys, params).compile() for f in (
        lambda k, p: initial.crumpled(k, physics, p).positions, lambda k, p: _reference_crumpled(k, physics, p)))
    positions = np.asarray(ours(keys, params))
    np.testing.assert_array_equal(positions, np.asarray(reference(keys, params)))
    layered = np.ptp(positions[..., 2], axis=1) > 0.01
    assert layered.sum() >= 3, np.ptp(positions[..., 2], axis=1)  # crumpled: layers over layers
    # and the compiled program holds one copy of the physics step, not three: about half the reference's fused
    # kernels (the rest is the same in both)
    fusions = [f.as_text().count("fusion(") for f in (ours, reference)]
    assert fusions[0] < 0.7 * fusions[1], fusions
