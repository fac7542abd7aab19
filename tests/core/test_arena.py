import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.core import episodes


@pytest.fixture(scope="module")
def arena():
    return jarena.build_arena("classic|domain:cartpole,task:balance")


def test_reset_and_step_info(arena):
    state, info = arena.reset(jax.random.key(0))
    assert info.observation["state"].shape == (4,) and info.observation["state"].dtype == jnp.float32
    assert int(info.step) == 0 and float(info.reward) == 0.0
    assert episodes.TRAIN_LOW <= int(info.episode) < episodes.TRAIN_HIGH
    state, info = arena.step(state, 1)
    assert int(info.step) == 1 and float(info.reward) == 1.0
    assert info.reward.dtype == jnp.float32 and info.terminated.dtype == jnp.bool_


def test_episode_ids_are_reproducible_and_splits_disjoint(arena):
    _, a = arena.reset(jax.random.key(1), episode=5)
    _, b = arena.reset(None, episode=5)
    _, c = arena.reset(None, episode=6)
    np.testing.assert_array_equal(a.observation["state"], b.observation["state"])
    assert not np.array_equal(a.observation["state"], c.observation["state"])
    ev, val, train = (set(arena.episodes(s)[:1000]) for s in ("eval", "val", "train"))
    assert len(arena.episodes("eval")) == 100 and len(arena.episodes("val")) == 20
    assert not (ev & val) and not (ev & train) and not (val & train)
    assert arena.episodes("train").start > max(arena.episodes("val"))
    with pytest.raises(ValueError, match="valid splits"):
        arena.episodes("test")


def test_reset_by_episode_is_jittable_without_retracing(arena):
    reset = jax.jit(lambda e: arena.reset(None, episode=e))
    _, a = reset(3)
    _, b = reset(4)
    assert reset._cache_size() == 1
    assert int(a.episode) == 3 and int(b.episode) == 4


def test_wrong_action_is_a_clear_error(arena):
    state, _ = arena.reset(jax.random.key(0))
    with pytest.raises(jarena.SpecError, match=r"action: expected a scalar integer in \[0, 2\)"):
        arena.step(state, jnp.zeros(2, jnp.int32))
    with pytest.raises(jarena.SpecError, match="action"):
        jax.jit(arena.step)(state, jnp.float32(1.0))


def test_reset_needs_key_or_episode(arena):
    with pytest.raises(ValueError, match="needs a key"):
        arena.reset()


def test_no_op_sample_action_privileged(arena):
    assert int(arena.no_op()) == 0
    assert bool(arena.action_spec.contains(arena.sample_action(jax.random.key(0))))
    state, _ = arena.reset(jax.random.key(0))
    assert arena.privileged(state).physics.x.shape == ()


def test_params_change_dynamics_under_vmap(arena):
    params = arena.default_params()
    masses = jnp.array([0.5, 1.0, 4.0])
    batched = jax.vmap(lambda m: params.replace(dynamics=params.dynamics.replace(masscart=m)))(masses)
    states, _ = jax.vmap(lambda p: arena.reset(None, p, episode=0))(batched)
    _, infos = jax.jit(jax.vmap(arena.step, in_axes=(0, None, 0)))(states, jnp.int32(1), batched)
    x_dot = np.asarray(infos.observation["state"][:, 1])
    assert x_dot[0] > x_dot[1] > x_dot[2]  # lighter carts accelerate more


def test_specs(arena):
    assert arena.spec.action == jarena.Discrete(2)
    assert arena.spec.observation["state"].shape == (4,)
    assert arena.max_episode_steps == 500


def test_seed_keys_draw_distinct_training_episodes(arena):
    ids = {int(arena.reset(jax.random.key(seed))[1].episode) for seed in range(64)}
    assert len(ids) == 64
    assert min(ids) >= episodes.TRAIN_LOW
