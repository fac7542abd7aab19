"""The point-mass domain and its goal-reaching task."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.arenas.classic import point_mass

ARENA = "classic|domain:point_mass,task:reach"
EPISODES = 64


@functools.cache
def compiled():
    arena = jarena.build_arena(ARENA)
    return arena, jax.jit(arena.reset), jax.jit(arena.step)


def pd_action(info, kp=4.0, kd=3.0):
    position, velocity = info.observation["state"][..., :2], info.observation["state"][..., 2:]
    return jnp.clip(kp * (info.goal - position) - kd * velocity, -1.0, 1.0)


@functools.cache
def rollout(policy: str):
    """``EPISODES`` full episodes (one per eval episode id) under ``policy``; infos stacked over time."""
    arena = jarena.build_arena(ARENA)
    steps = arena.max_episode_steps

    def act(key, info):
        if policy == "pd":
            return pd_action(info)
        if policy == "random":
            return jax.random.uniform(key, (2,), jnp.float32, -1.5, 1.5)  # some beyond the bounds: clipped
        return jnp.asarray([1.0, -1.0], jnp.float32)  # "wall": push into a corner

    def episode(episode_id):
        state, info = arena.reset(episode=episode_id)

        def body(carry, key):
            state, info = carry
            state, info = arena.step(state, act(key, info))
            return (state, info), (info, state.physics)

        _, (infos, physics) = jax.lax.scan(body, (state, info), jax.random.split(jax.random.key(episode_id), steps))
        return info, infos, physics

    return jax.jit(jax.vmap(episode))(jnp.arange(EPISODES, dtype=jnp.int32))


def test_spec_and_defaults():
    arena, reset, _ = compiled()
    assert arena.goal_dim == 2
    assert arena.max_episode_steps == 200
    assert arena.action_spec == jarena.Box(-1.0, 1.0, (2,))
    assert arena.observation_spec["state"].shape == (4,)
    assert ARENA in jarena.list_arenas("classic") and ARENA not in jarena.list_arenas("benchmark")
    _, info = reset(jax.random.key(0))
    assert info.observation["state"].dtype == jnp.float32
    np.testing.assert_array_equal(info.observation["state"][2:], 0.0)  # starts at rest


def test_goal_in_info_and_differs_across_episodes():
    arena, reset, step = compiled()
    goals = np.stack([np.asarray(reset(episode=e)[1].goal) for e in range(20)])
    assert goals.shape == (20, 2)
    assert np.all((goals >= -0.8) & (goals <= 0.8))
    assert len({tuple(g) for g in goals}) == 20
    # An episode id fixes its goal; steps keep it.
    state, info = reset(episode=3)
    np.testing.assert_array_equal(info.goal, goals[3])
    state, info = step(state, jnp.asarray([0.3, -0.2], jnp.float32))
    np.testing.assert_array_equal(info.goal, goals[3])


def test_dense_reward_is_minus_distance():
    _, infos, physics = rollout("random")
    distance = np.linalg.norm(np.asarray(physics.position) - np.asarray(infos.goal), axis=-1)
    np.testing.assert_allclose(np.asarray(infos.reward), -distance, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(np.asarray(infos.metrics["distance"]), distance, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(np.asarray(infos.success), distance < 0.05)
    assert not np.any(np.asarray(infos.terminated))


def test_pd_controller_reaches_the_goal():
    _, infos, _ = rollout("pd")
    success = np.asarray(infos.success)
    assert success.any(axis=1).all()  # every episode reaches the goal within the time limit
    assert success[:, -1].all()  # and holds it
    truncated = np.asarray(infos.truncated)
    assert not truncated[:, :-1].any() and truncated[:, -1].all()


@pytest.mark.parametrize("policy", ["random", "wall"])
def test_position_stays_in_bounds(policy):
    arena, _, _ = compiled()
    _, infos, physics = rollout(policy)
    position, velocity = np.asarray(physics.position), np.asarray(physics.velocity)
    assert np.all(np.abs(position) <= 1.0)
    assert np.all(np.abs(velocity) <= 2.0)
    obs = np.asarray(infos.observation["state"])
    spec = arena.observation_spec["state"]
    assert np.all((obs >= spec.low) & (obs <= spec.high))
    at_wall = np.abs(position) == 1.0
    if policy == "wall":  # pushed into the corner (1, -1): it gets there and stays, at rest
        assert at_wall[:, -1].all()
        np.testing.assert_array_equal(position[:, -1], np.broadcast_to([1.0, -1.0], (EPISODES, 2)))
        np.testing.assert_array_equal(velocity[:, -1], 0.0)
    np.testing.assert_array_equal(velocity[at_wall], 0.0)  # clipped axes stop


def test_step_is_semi_implicit_euler():
    params = point_mass.dynamics().default_params()
    state = point_mass.PointMassState(position=jnp.asarray([0.2, -0.3], jnp.float32),
                                      velocity=jnp.asarray([0.5, -0.1], jnp.float32))
    nxt = point_mass.step(state, jnp.asarray([1.0, 3.0], jnp.float32), params)  # 3 is clipped to 1
    v = np.array([0.5, -0.1]) + 0.05 * (np.array([1.0, 1.0]) - 1.0 * np.array([0.5, -0.1]))
    np.testing.assert_allclose(nxt.velocity, v, rtol=1e-6)
    np.testing.assert_allclose(nxt.position, np.array([0.2, -0.3]) + 0.05 * v, rtol=1e-6)
    # Into the wall along x only: x stops at the wall, y slides on.
    state = point_mass.PointMassState(position=jnp.asarray([0.999, 0.0], jnp.float32),
                                      velocity=jnp.asarray([1.0, 0.5], jnp.float32))
    nxt = point_mass.step(state, jnp.zeros((2,), jnp.float32), params)
    assert float(nxt.position[0]) == 1.0 and float(nxt.velocity[0]) == 0.0
    assert float(nxt.velocity[1]) > 0.0 and float(nxt.position[1]) > 0.0


def test_sparse_variant_builds():
    arena = jarena.build_arena("classic|domain:point_mass,task:reach(reward=sparse,threshold=0.1)")
    state, info = arena.reset(episode=0)
    state, info = arena.step(state, jnp.zeros((2,), jnp.float32))
    assert float(info.reward) == float(info.success)
