"""Diffusion Policy's padded windows and its [-1, 1] normaliser."""

import jax
import jax.numpy as jnp
import numpy as np

from jarena_agents.diffusion import data


def test_windows_cover_every_padded_start_and_repeat_the_edge_steps():
    lengths = np.array([5, 9, 12], np.int32)
    # each stored value is its row number: trajectory i's observations start at its first action row + i
    steps, n = int(lengths.sum()), lengths.size
    stored = {"observation": {"state": np.arange(steps + n, dtype=np.float32)[:, None]},
              "action": np.arange(steps, dtype=np.float32)[:, None] + 1000.0, "goal": {}}
    horizon, obs_horizon, action_steps = 8, 2, 4
    sample = jax.jit(data.sample_windows, static_argnums=(3, 4, 5, 6))
    observation, goal, actions = sample(stored, jnp.asarray(lengths), jax.random.key(0), 512, horizon, obs_horizon,
                                        action_steps)
    assert observation["state"].shape == (512, obs_horizon, 1) and actions.shape == (512, horizon, 1) and goal == {}
    first_action = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    seen = set()
    for obs, act in zip(np.asarray(observation["state"][..., 0]), np.asarray(actions[..., 0]), strict=True):
        i = int(np.searchsorted(first_action, act[-1] - 1000.0, side="right")) - 1  # the window's trajectory
        length = int(lengths[i])
        local = act - 1000.0 - first_action[i]  # the action steps the window holds, padding repeated
        starts = [s for s in range(-(obs_horizon - 1), length - horizon + action_steps)
                  if np.array_equal(local, np.clip(s + np.arange(horizon), 0, length - 1))]
        assert len(starts) == 1, local
        start = starts[0]
        expected = np.clip(start + np.arange(horizon), 0, length - 1)
        np.testing.assert_array_equal(obs - first_action[i] - i, expected[:obs_horizon])  # obs t pairs action t
        seen.add((i, start))
    # every start from -(T_o - 1) to T - H + T_a - 1 is drawn, and no other
    expected_starts = {(i, s) for i, t in enumerate(lengths)
                       for s in range(-(obs_horizon - 1), int(t) - horizon + action_steps)}
    assert seen == expected_starts


def test_limits_map_onto_minus_one_one_and_back():
    limits = data.limits_of(np.array([[0.0, 3.0, -2.0], [4.0, 3.0, 2.0], [2.0, 3.0, 0.0]], np.float32))
    np.testing.assert_array_equal(limits.low, [0.0, 3.0, -2.0])
    x = jnp.array([[0.0, 3.0, -2.0], [4.0, 3.0, 2.0], [1.0, 3.0, 1.0]])
    unit = jax.jit(data.to_unit)(limits, x)
    np.testing.assert_allclose(unit, [[-1, 0, -1], [1, 0, 1], [-0.5, 0, 0.5]], atol=1e-6)  # a constant column: 0
    np.testing.assert_allclose(jax.jit(data.from_unit)(limits, unit), x, atol=1e-6)
