"""The classic arenas against Gymnasium's own environments, step by step from the same states."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena

gym = pytest.importorskip("gymnasium")

STEPS = 200
TOL = dict(rtol=1e-5, atol=1e-5)


@dataclasses.dataclass(frozen=True)
class Case:
    arena: str
    gym_id: str
    to_gym: Callable  # physics -> Gymnasium's ``state`` vector
    reset_low: tuple  # Gymnasium's reset ranges of that vector
    reset_high: tuple
    policy: Callable  # (rng, physics as a numpy vector) -> numpy action
    to_gym_action: Callable = lambda a: a
    terminates: bool = True  # the policy reaches a terminal state within STEPS steps
    wrapped: tuple = ()  # indices of angles that the dynamics wraps to [-pi, pi]


def _cartpole_policy(rng, s):
    return np.asarray(rng.integers(2), np.int32)


def _pendulum_policy(rng, s):
    return rng.uniform(-2.5, 2.5, (1,)).astype(np.float32)  # some out of [-2, 2]: both clip


def _mountain_car_policy(rng, s):
    if rng.random() < 0.8:  # pump energy: push along the velocity
        return np.asarray([1.0 if s[1] >= 0 else -1.0], np.float32)
    return rng.uniform(-1.5, 1.5, (1,)).astype(np.float32)


def _acrobot_policy(rng, s):
    if rng.random() < 0.8:  # pump energy: torque along the second joint's velocity
        return np.asarray(2 if s[3] > 0 else 0, np.int32)
    return np.asarray(rng.integers(3), np.int32)


CASES = {
    "cartpole": Case("classic|domain:cartpole,task:balance", "CartPole-v1",
                     lambda p: [p.x, p.x_dot, p.theta, p.theta_dot], (-0.05,) * 4, (0.05,) * 4, _cartpole_policy,
                     to_gym_action=int),
    "pendulum": Case("classic|domain:pendulum,task:swingup", "Pendulum-v1", lambda p: [p.theta, p.theta_dot],
                     (-np.pi, -1.0), (np.pi, 1.0), _pendulum_policy, terminates=False),
    "mountain_car": Case("classic|domain:mountain_car,task:continuous", "MountainCarContinuous-v0",
                         lambda p: [p.position, p.velocity], (-0.6, 0.0), (-0.4, 0.0), _mountain_car_policy),
    "acrobot": Case("classic|domain:acrobot,task:swingup", "Acrobot-v1",
                    lambda p: [p.theta1, p.theta2, p.theta1_dot, p.theta2_dot], (-0.1,) * 4, (0.1,) * 4,
                    _acrobot_policy, to_gym_action=int, wrapped=(0, 1)),
}
NAMES = list(CASES)


@functools.cache
def compiled(name):
    """The arena and its jit-compiled reset, step and batched reset (compiled once per arena)."""
    arena = jarena.build_arena(CASES[name].arena)
    return arena, jax.jit(arena.reset), jax.jit(arena.step), jax.jit(jax.vmap(arena.reset))


def gym_state(case, physics):
    return np.asarray(jax.device_get(case.to_gym(physics)), np.float64)


def assert_same_state(case, physics, theirs, where):
    """Our physics state against Gymnasium's ``state`` (wrapped angles compared modulo 2 pi)."""
    ours, theirs = gym_state(case, physics), np.asarray(theirs, np.float64)
    diff = ours - theirs
    for i in case.wrapped:
        diff[i] = (diff[i] + np.pi) % (2 * np.pi) - np.pi
        assert -np.pi - 1e-6 <= ours[i] <= np.pi + 1e-6, where
    assert np.all(np.abs(diff) <= TOL["atol"] + TOL["rtol"] * np.abs(theirs)), f"{where}: {ours} vs {theirs}"


def test_listed_as_benchmarks():
    assert set(jarena.list_arenas("benchmark")) >= {case.arena for case in CASES.values()}


@pytest.mark.parametrize("name", NAMES)
def test_steps_match_gymnasium(name):
    case = CASES[name]
    arena, reset, step, _ = compiled(name)
    low = np.asarray(arena.observation_spec["state"].low, np.float32)
    high = np.asarray(arena.observation_spec["state"].high, np.float32)
    env = gym.make(case.gym_id).unwrapped
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    key = jax.random.key(0)
    state, info = reset(key)
    terminations = 0
    for t in range(STEPS):
        s = gym_state(case, state.physics)
        action = case.policy(rng, s)
        env.state = s.copy()
        if name == "cartpole":
            env.steps_beyond_terminated = None  # a fresh state: no "stepped after termination" handling
        obs, reward, terminated, truncated, _ = env.step(case.to_gym_action(action))
        state, info = step(state, jnp.asarray(action))
        where = f"{name} step {t} from state {s} with action {action}"
        np.testing.assert_allclose(np.asarray(info.observation["state"]), obs, **TOL, err_msg=where)
        np.testing.assert_allclose(float(info.reward), float(reward), **TOL, err_msg=where)
        assert bool(info.terminated) == terminated, where
        assert_same_state(case, state.physics, env.state, where)
        assert not truncated
        assert np.all((low <= info.observation["state"]) & (info.observation["state"] <= high)), where
        if name != "pendulum":  # success is "reached the goal" / "not failed"
            assert bool(info.success) == (terminated if name != "cartpole" else not terminated), where
        terminations += int(terminated)
        if info.terminated or info.truncated:
            key, sub = jax.random.split(key)
            state, info = reset(sub)
    assert terminations > 0 or not case.terminates, f"{name}: no terminal step was compared"


# Hand-picked states at the edges of each model: thresholds, clips, walls and angle wraps.
EDGE_STATES = {
    "cartpole": [[2.39, 1.0, 0.2, 1.0], [-2.39, -1.0, -0.2, -1.0], [0.0, 0.0, 0.2094, 0.5], [1.0, 3.0, -0.1, -2.0]],
    "pendulum": [[0.0, 7.9], [np.pi, -7.99], [7.5, 3.0], [-20.0, 8.0], [np.pi - 1e-3, 0.0], [0.05, 0.5]],
    "mountain_car": [[-1.19, -0.07], [-1.2, -0.01], [-1.2, 0.0], [0.44, 0.07], [0.59, 0.07], [0.45, 0.0],
                     [-0.5, 0.069], [-0.5, -0.069]],
    "acrobot": [[3.1, 3.1, 12.0, 28.0], [-3.1, -3.1, -12.0, -28.0], [np.pi, 0.0, 0.0, 0.0], [0.1, 0.1, 12.5, -28.2],
                [2.0, -1.0, -3.0, 5.0], [-2.5, 2.8, 1.0, -20.0]],
}
EDGE_ACTIONS = {"cartpole": [0, 1], "pendulum": [[-3.0], [-2.0], [0.0], [1.5], [3.0]],
                "mountain_car": [[-2.0], [-1.0], [0.0], [0.5], [1.0], [2.0]], "acrobot": [0, 1, 2]}


@pytest.mark.parametrize("name", NAMES)
def test_edge_states_match_gymnasium(name):
    case = CASES[name]
    arena, reset, step, _ = compiled(name)
    env = gym.make(case.gym_id).unwrapped
    env.reset(seed=0)
    state, _ = reset(jax.random.key(0))
    physics_type = type(state.physics)
    dtype = np.int32 if name in ("cartpole", "acrobot") else np.float32
    for s in EDGE_STATES[name]:
        physics = physics_type(*[jnp.asarray(v, jnp.float32) for v in s])
        for a in EDGE_ACTIONS[name]:
            action = np.asarray(a, dtype)
            env.state = gym_state(case, physics)
            if name == "cartpole":
                env.steps_beyond_terminated = None
            obs, reward, terminated, _, _ = env.step(case.to_gym_action(action))
            next_state, info = step(state.replace(physics=physics), jnp.asarray(action))
            where = f"{name} from state {s} with action {a}"
            np.testing.assert_allclose(np.asarray(info.observation["state"]), obs, **TOL, err_msg=where)
            np.testing.assert_allclose(float(info.reward), float(reward), **TOL, err_msg=where)
            assert bool(info.terminated) == terminated, where
            assert_same_state(case, next_state.physics, env.state, where)


def test_pendulum_success_and_upright():
    arena, reset, step, _ = compiled("pendulum")
    state, info = reset(jax.random.key(0))
    assert set(info.metrics) == {"upright"}
    seen = set()
    for theta, theta_dot in [(0.0, 0.0), (0.12, 0.0), (-0.05, 0.9), (0.0, 1.5), (2 * np.pi, 0.0), (np.pi, 0.0)]:
        physics = type(state.physics)(jnp.float32(theta), jnp.float32(theta_dot))
        _, info = step(state.replace(physics=physics), jnp.zeros((1,), jnp.float32))
        cos, sin, speed = np.asarray(info.observation["state"])  # success is judged after the step
        assert bool(info.success) == (abs(np.arctan2(sin, cos)) < 0.1 and abs(speed) < 1.0), (theta, theta_dot)
        seen.add(bool(info.success))
        np.testing.assert_allclose(float(info.metrics["upright"]), cos, rtol=1e-6)
        assert not bool(info.terminated)
    assert seen == {True, False}


@pytest.mark.parametrize("name", NAMES)
def test_time_limit_matches_gymnasium(name):
    case = CASES[name]
    arena, reset, step, _ = compiled(name)
    limit = gym.spec(case.gym_id).max_episode_steps
    assert arena.max_episode_steps == limit

    # Gymnasium's TimeLimit: hold the state at its (non-terminal) initial value and count steps.
    env = gym.make(case.gym_id)
    env.reset(seed=0)
    start = np.array(env.unwrapped.state, np.float64)
    no_op = case.to_gym_action(np.asarray(jax.device_get(arena.no_op())))
    gym_steps = 0
    while True:
        env.unwrapped.state = start.copy()
        _, _, terminated, truncated, _ = env.step(no_op)
        gym_steps += 1
        assert not terminated
        if truncated:
            break
    assert gym_steps == limit

    # Ours: the time limit counts steps whatever the physics does (the episode may terminate first).
    state, info = reset(jax.random.key(1))
    no_op = arena.no_op()
    truncated = []
    for _ in range(limit):
        state, info = step(state, no_op)
        truncated.append(bool(info.truncated))
    assert truncated == [False] * (limit - 1) + [True]


@pytest.mark.parametrize("name", NAMES)
def test_reset_distribution_matches_gymnasium(name):
    case = CASES[name]
    arena, _, _, batch_reset = compiled(name)
    low, high = np.asarray(case.reset_low), np.asarray(case.reset_high)

    env = gym.make(case.gym_id).unwrapped  # the declared ranges are Gymnasium's
    theirs = []
    for seed in range(200):
        env.reset(seed=seed)
        theirs.append(np.array(env.state, np.float64))
    theirs = np.stack(theirs)
    assert np.all((theirs >= low) & (theirs <= high))

    states, infos = batch_reset(jax.random.split(jax.random.key(0), 4096))
    ours = np.stack([np.asarray(v, np.float64) for v in case.to_gym(states.physics)], axis=-1)
    assert np.all((ours >= low - 1e-6) & (ours <= high + 1e-6))
    width = high - low
    np.testing.assert_allclose(ours.min(0), low, atol=0.01 * width.max())  # the whole range is covered
    np.testing.assert_allclose(ours.max(0), high, atol=0.01 * width.max())
    assert not np.any(infos.terminated | infos.truncated)
    assert all(leaf.dtype == jnp.float32 for leaf in jax.tree_util.tree_leaves(states.physics))
    assert infos.observation["state"].dtype == jnp.float32
    assert len(np.unique(np.asarray(infos.episode))) > 4000  # distinct episodes
