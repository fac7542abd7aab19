"""The arena model: exact arena steps, and clear errors for arenas and states it cannot plan with."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena_agents.planners import Model, arena_model


def test_arena_model_steps_like_the_arena():
    arena = jarena.build_arena("classic|domain:pendulum,time_limit:2")
    model = arena_model(arena)
    state, _ = jax.jit(arena.reset)(jax.random.key(0))
    step = jax.jit(model.step)
    s1, r1, d1 = step(state, jnp.array([1.0]))
    s2, info = jax.jit(arena.step)(state, jnp.array([1.0]))
    np.testing.assert_array_equal(s1.physics.theta, s2.physics.theta)
    assert float(r1) == float(info.reward) and not bool(d1)
    _, _, d2 = step(s1, jnp.array([1.0]))
    assert bool(d2)  # truncated by the time limit
    assert model.name == "classic|domain:pendulum,time_limit:2"
    np.testing.assert_array_equal(model.no_op, [0.0])


def test_arena_model_rejects_discrete_actions():
    with pytest.raises(ValueError, match="bounded continuous action spec.*Discrete\\(2\\)"):
        arena_model(jarena.build_arena("classic|domain:cartpole"))


def test_check_state_names_the_mismatch():
    model = arena_model(jarena.build_arena("classic|domain:pendulum"))

    def states(string):  # shapes of a batch of 3 states, without running anything
        return jax.eval_shape(lambda: jarena.batch_reset(jarena.build_arena(string), jax.random.key(0), 3)[0])

    state = states("classic|domain:pendulum")
    model.check_state(state, batch_dims=1)
    other = states("classic|domain:pendulum,action:repeat(2)")
    with pytest.raises(ValueError, match="does not fit model 'classic\\|domain:pendulum'.*structure"):
        model.check_state(other, batch_dims=1)
    bad = state.replace(physics=state.physics.replace(theta=jax.ShapeDtypeStruct((3, 2), jnp.float32)))
    with pytest.raises(ValueError, match="state.physics.theta has shape \\(2,\\)"):
        model.check_state(bad, batch_dims=1)
    Model(step=model.step, action_spec=model.action_spec, no_op=model.no_op).check_state(bad)  # unchecked
