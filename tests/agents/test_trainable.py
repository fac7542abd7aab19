import jax
import numpy as np

from jarena import build_arena
from jarena_agents import TrainableAgent, build_agent


def test_save_and_load_round_trip_the_train_state(tmp_path):
    arena = build_arena("classic|domain:cartpole")
    agent = build_agent("ppo", {"num_arenas": 2, "rollout_length": 8, "hidden": (8,)})
    assert isinstance(agent, TrainableAgent)
    state = jax.jit(agent.init_training, static_argnums=1)(jax.random.key(3), arena)
    state, _ = jax.jit(agent.train, static_argnums=(1, 2))(state, arena, 2)
    agent.save(tmp_path / "ckpt", state, step=2)
    loaded = agent.load(tmp_path / "ckpt", arena)
    raw = lambda x: jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x
    same = jax.tree_util.tree_map(lambda a, b: np.array_equal(raw(a), raw(b)), state, loaded)
    assert all(jax.tree_util.tree_leaves(same))
    # continuing from the loaded state equals continuing from the original
    a, _ = jax.jit(agent.train, static_argnums=(1, 2))(state, arena, 1)
    b, _ = jax.jit(agent.train, static_argnums=(1, 2))(loaded, arena, 1)
    np.testing.assert_array_equal(jax.tree_util.tree_leaves(a.params)[0], jax.tree_util.tree_leaves(b.params)[0])


def test_load_without_checkpoint_is_a_clear_error(tmp_path):
    import pytest
    agent = build_agent("ppo", {"num_arenas": 2, "rollout_length": 8, "hidden": (8,)})
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        agent.load(tmp_path / "none", build_arena("classic|domain:cartpole"))
