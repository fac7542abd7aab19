"""The cloth flattening oracle: it acts the same in any batch, and pulls the worst corner to its flat goal."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena_agents.registry import build_agent


@pytest.mark.parametrize("name,task", [("oracle_cloth_flattening", "flattening"),
                                       ("oracle_cloth_folding", "side_fold")])
def test_the_oracle_acts_the_same_to_the_bit_in_any_batch(name, task):
    # a last-bit difference in an action changes where a crumpled cloth lands, and the episode diverges: the
    # oracles' sums run in a fixed order, unlike matmuls and jnp.sum, whose order follows the batch size
    arena = jarena.build_arena(f"cloth|task:{task},initial:crumpled,particles:24,resolution:32,horizon:2")
    oracle = build_agent(name)

    @jax.jit
    def first_actions(episodes):
        state, info = jax.vmap(lambda e: arena.reset(episode=e))(episodes)
        agent_state = oracle.init(jax.random.key(0), arena.spec, episodes.shape[0])
        return oracle.act(agent_state, info, jax.random.key(1), jax.vmap(arena.privileged)(state))[0]

    whole = np.asarray(first_actions(jnp.arange(9)))
    for part in (jnp.array([4]), jnp.array([2, 7, 0]), jnp.arange(9)[::-1]):
        np.testing.assert_array_equal(np.asarray(first_actions(part)), whole[np.asarray(part)])
