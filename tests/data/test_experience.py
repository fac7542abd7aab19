import jax
import numpy as np

import jarena
import jarena_agents
from jarena.data import experience_spec, make_buffer, transition_from


def test_transitions_from_a_rollout_keep_terminal_observations_and_fill_a_buffer():
    arena = jarena.build_arena("classic|domain:cartpole,task:balance")
    agent = jarena_agents.build_agent("random")
    key = jax.random.key(0)
    start = jarena.batch_reset(arena, jax.random.fold_in(key, 1), 4)
    rollout = jarena.perform_parallel(agent, arena, key, 4, 60, start=start)
    before = jax.tree_util.tree_map(lambda first, rest: np.concatenate([first[None], rest[:-1]]),
                                    start[1], rollout.infos)
    items = transition_from(before, rollout.actions, rollout.infos)  # leaves (T, B, ...)
    assert jax.tree_util.tree_structure(items) == jax.tree_util.tree_structure(experience_spec(arena))
    done = np.asarray(items.done)
    assert done.sum() > 4  # random cart-pole episodes last ~20 steps
    # within an episode the next observation is the following step's observation ...
    obs, nxt = np.asarray(items.observation["state"]), np.asarray(items.next_observation["state"])
    np.testing.assert_array_equal(nxt[:-1][~done[:-1]], obs[1:][~done[:-1]])
    # ... at its end it is the terminal observation, and the next item starts a new episode at step 0
    assert (np.abs(nxt[:-1][done[:-1]][:, 2]) > 0.2).all()  # pole angle beyond the 12 degree limit
    np.testing.assert_array_equal(np.asarray(items.step)[1:][done[:-1]], 0)
    assert (np.asarray(items.episode)[1:][done[:-1]] != np.asarray(items.episode)[:-1][done[:-1]]).all()

    buffer = make_buffer(4, 4 * 64, 16, mode="trajectory", length=64)
    state = jax.jit(buffer.add)(buffer.init(experience_spec(arena)), items)
    sample = jax.jit(buffer.sample)(state, jax.random.key(2))
    steps = np.asarray(sample.experience.step)
    lengths = np.asarray(sample.mask).sum(1)
    assert (steps[:, 0] == 0).all() and (lengths > 0).all()
    assert np.asarray(sample.experience.done)[np.arange(16), lengths - 1].all()
