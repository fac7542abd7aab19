"""Sampling helpers: rollout scores against a plain Python loop of ``arena.step``, sampling, plan shifts."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena_agents.planners import arena_model
from jarena_agents.planners.sampling import (
    action_bounds,
    initial_plan,
    rollout_returns,
    sample_plans,
    shift_plan,
    warm_start_fill,
)


def _python_loop_returns(arena, state, plans):
    """Sum of rewards of each plan, stepping ``arena.step`` one action at a time until the episode ends."""
    step = jax.jit(arena.step)
    out = []
    for plan in np.asarray(plans):
        s, total = state, 0.0
        for action in plan:
            s, info = step(s, jnp.asarray(action))
            total += float(info.reward)
            if bool(info.done):
                break
        out.append(total)
    return np.asarray(out)


def test_rollout_returns_equal_python_loop_sums_with_truncation():
    # A 10-step time limit inside a 14-step horizon: rewards after the truncation must not count.
    arena = jarena.build_arena("classic|domain:pendulum,time_limit:10")
    model = arena_model(arena)
    state, _ = arena.reset(jax.random.key(3))
    state, _ = arena.step(state, jnp.array([0.5]))  # start mid-episode: truncation after 9 more steps
    low, high = action_bounds(model)
    plans = sample_plans(jax.random.key(1), initial_plan(model, 14), 1.5, 5, low, high)
    got = jax.jit(lambda s, p: rollout_returns(model, s, p))(state, plans)
    want = _python_loop_returns(arena, state, plans)
    np.testing.assert_allclose(np.asarray(got), want, rtol=1e-5, atol=1e-4)
    # and the truncation matters: summing all 14 steps would differ
    assert not np.allclose(_python_loop_returns(jarena.build_arena("classic|domain:pendulum"), state, plans), want)


def test_rollout_returns_equal_python_loop_sums_with_termination():
    # Mountain car just before the goal: full throttle terminates within the horizon, reverse does not.
    arena = jarena.build_arena("classic|domain:mountain_car")
    model = arena_model(arena)
    state, _ = arena.reset(jax.random.key(0))
    state = state.replace(physics=state.physics.replace(position=jnp.float32(0.40), velocity=jnp.float32(0.03)))
    plans = jnp.stack([jnp.full((8, 1), 1.0), jnp.full((8, 1), -1.0), jnp.linspace(-1, 1, 8)[:, None]])
    got = np.asarray(rollout_returns(model, state, plans))
    want = _python_loop_returns(arena, state, plans)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-4)
    assert got[0] > 50  # the goal bonus (100) counted once, then nothing


def test_sample_plans_include_the_mean_and_respect_bounds():
    low, high = jnp.array([-2.0, 0.0]), jnp.array([2.0, 1.0])
    mean = jnp.tile(jnp.array([1.5, 0.5]), (6, 1))
    plans = sample_plans(jax.random.key(0), mean, jnp.array([3.0, 1.0]), 64, low, high)
    assert plans.shape == (64, 6, 2)
    np.testing.assert_array_equal(plans[0], mean)
    assert bool(jnp.all((plans >= low) & (plans <= high)))
    assert float(jnp.std(plans[1:, :, 0])) > 0.5  # really sampled
    np.testing.assert_array_equal(sample_plans(jax.random.key(0), mean, 0.0, 3, low, high), jnp.stack([mean] * 3))
    np.testing.assert_array_equal(plans, sample_plans(jax.random.key(0), mean, jnp.array([3.0, 1.0]), 64, low, high))


def test_shift_plan_drops_the_first_action_and_pads():
    model = arena_model(jarena.build_arena("classic|domain:point_mass"))
    plan = jnp.arange(8.0).reshape(4, 2)
    np.testing.assert_array_equal(shift_plan(plan, warm_start_fill(plan, model, "last")),
                                  [[2, 3], [4, 5], [6, 7], [6, 7]])
    np.testing.assert_array_equal(shift_plan(plan, warm_start_fill(plan, model, "no_op")),
                                  [[2, 3], [4, 5], [6, 7], [0, 0]])
    np.testing.assert_array_equal(initial_plan(model, 3), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="warm_start must be one of \\['last', 'no_op'\\]"):
        warm_start_fill(plan, model, "zeros")
