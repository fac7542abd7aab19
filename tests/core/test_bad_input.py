"""Bad input to arenas and specs gets a clear error: values given eagerly, params, episode ids."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.core.spec import Box, Discrete, SpecError


# ---------------------------------------------------------------------------------------------- action values
@pytest.mark.parametrize("action", [7, -1, 2, jnp.int32(7), np.int64(-1)])
def test_out_of_range_discrete_action_is_a_spec_error_naming_the_range(cartpole, action):
    state, _ = cartpole.reset(jax.random.key(0))
    with pytest.raises(SpecError, match=rf"action: {int(action)} is out of range; expected a scalar integer in "
                                        r"\[0, 2\) \(Discrete\(2\)\)"):
        cartpole.step(state, action)


def test_discrete_values_are_checked_only_when_concrete():
    spec = Discrete(3)
    assert int(spec.validate(2)) == 2
    with pytest.raises(SpecError, match=r"3 is out of range.*\[0, 3\)"):
        spec.validate(3)
    # under jit (and vmap) the value is a tracer: unknown, so not checked (the arena faults it instead)
    assert int(jax.jit(spec.validate)(5)) == 5
    np.testing.assert_array_equal(jax.vmap(spec.validate)(jnp.array([-1, 4])), [-1, 4])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_box_action_is_a_spec_error(pendulum, bad):
    state, _ = pendulum.reset(jax.random.key(0))
    with pytest.raises(SpecError, match="action: non-finite values"):
        pendulum.step(state, jnp.array([bad], jnp.float32))
    with pytest.raises(SpecError, match="non-finite"):
        Box(-1, 1, (2,)).validate(np.array([0.0, bad]))
    assert jax.jit(Box(-1, 1, (1,)).validate)(jnp.array([bad])).shape == (1,)  # traced: not checked


def test_box_action_outside_its_bounds_is_clipped_not_refused(pendulum):
    state, _ = pendulum.reset(jax.random.key(0))
    _, far = pendulum.step(state, jnp.array([50.0], jnp.float32))
    _, edge = pendulum.step(state, jnp.array([2.0], jnp.float32))  # the bound: Pendulum-v1 clips to [-2, 2]
    np.testing.assert_array_equal(far.observation["state"], edge.observation["state"])


# ---------------------------------------------------------------------------------------------- dtype rules
def test_float_action_into_an_integer_spec_is_refused(cartpole):
    state, _ = cartpole.reset(jax.random.key(0))
    with pytest.raises(SpecError, match=r"expected a scalar integer in \[0, 2\)"):
        cartpole.step(state, jnp.float32(1.0))
    with pytest.raises(SpecError, match=r"expected a scalar integer"):
        cartpole.step(state, 1.0)
    with pytest.raises(SpecError, match="expected a int array of dtype int32"):
        Box(0, 10, (2,), jnp.int32).validate(jnp.array([1.0, 2.0]))


def test_int_action_into_a_float_box_casts_as_astype_and_bools_are_refused(pendulum):
    box = Box(-1e9, 1e9, (3,))
    ints = jnp.array([3, -4, 2**24 + 1], jnp.int32)
    cast = box.validate(ints)
    assert cast.dtype == jnp.float32
    np.testing.assert_array_equal(cast, ints.astype(jnp.float32))  # 2^24 + 1 rounds as astype does
    state, _ = pendulum.reset(jax.random.key(0))
    _, from_int = pendulum.step(state, jnp.array([1], jnp.int32))
    _, from_float = pendulum.step(state, jnp.array([1.0], jnp.float32))
    np.testing.assert_array_equal(from_int.observation["state"], from_float.observation["state"])
    with pytest.raises(SpecError, match="expected a float array"):
        pendulum.step(state, jnp.array([True]))
    with pytest.raises(SpecError, match="expected a scalar integer"):
        Discrete(2).validate(jnp.bool_(True))


# ---------------------------------------------------------------------------------------------- params
def test_params_of_the_wrong_type_name_arena_params(cartpole):
    state, _ = cartpole.reset(jax.random.key(0))
    with pytest.raises(TypeError, match="step: params must be an ArenaParams.*got dict"):
        cartpole.step(state, 1, {"g": 1.0})
    with pytest.raises(TypeError, match="reset: params must be an ArenaParams.*got tuple"):
        cartpole.reset(jax.random.key(0), (1, 2, 3))


def test_params_of_the_wrong_structure_name_the_piece_and_what_was_expected(cartpole):
    params = cartpole.default_params()
    state, _ = cartpole.reset(jax.random.key(0))
    with pytest.raises(TypeError, match=r"params has the wrong structure.*\n  params.dynamics: expected a "
                                        r"CartPoleParams .*, got a dict"):
        cartpole.step(state, 1, params.replace(dynamics={"g": 1.0}))
    with pytest.raises(TypeError, match="params.task: expected a"):
        cartpole.reset(jax.random.key(0), params.replace(task=(1.0, 2.0)))
    with pytest.raises(TypeError, match="params.dynamics"):  # under jit too: the structure is static
        jax.jit(cartpole.step)(state, 1, params.replace(dynamics=()))


def test_params_check_accepts_changed_leaves_under_jit_and_vmap(cartpole):
    params = cartpole.default_params()
    assert cartpole.params_structure is cartpole.params_structure  # computed once
    batched = jax.tree_util.tree_map(lambda x: jnp.stack([jnp.asarray(x)] * 2), params)
    masses = batched.replace(dynamics=batched.dynamics.replace(masspole=jnp.array([0.1, 0.5])))
    states, infos = jarena.batch_reset(cartpole, jax.random.key(0), 2, masses, params_axis=0)
    _, infos = jax.jit(lambda s: jarena.batch_step(cartpole, s, jnp.ones(2, jnp.int32), masses, params_axis=0))(
        states)
    assert infos.reward.shape == (2,)


# ---------------------------------------------------------------------------------------------- episode ids
@pytest.mark.parametrize("episode", [-5, -1, 2**31])
def test_out_of_range_episode_id_is_refused_eagerly(cartpole, episode):
    with pytest.raises(ValueError, match=rf"reset: invalid episode id\(s\) \[{episode}\]; valid ids are in "
                                         r"\[0, 2\^31\)"):
        cartpole.reset(jax.random.key(0), cartpole.default_params(), episode=episode)


def test_episode_ids_under_jit_are_not_checked(cartpole):
    _, info = jax.jit(lambda e: cartpole.reset(None, episode=e))(-5)  # traced: unknown, so it cannot raise
    assert int(info.episode) == -5
    _, last = cartpole.reset(None, episode=2**31 - 1)
    assert int(last.episode) == 2**31 - 1
