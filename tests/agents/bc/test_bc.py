import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.core.spec import Box
from jarena.data import DatasetError, TrajectoryDataset, configs_for
from jarena.training import train_and_evaluate
from jarena_agents import networks
from jarena_agents.bc.agent import flatten, read_dataset, sample, to_unit

PENDULUM = "classic|domain:pendulum,task:swingup"
CARTPOLE = "classic|domain:cartpole,task:balance"


def demonstrations(path, oracle, arena, n, seed=1):
    """Collects ``n`` oracle trajectories into a dataset at ``path``; returns the oracle and its eval return."""
    agent = jarena_agents.build_agent(oracle, jarena.retrieve_config(oracle, arena))
    with TrajectoryDataset(path, "w", **configs_for(arena)) as dataset:
        jarena.collect(agent, arena, dataset, n, key=jax.random.key(seed), progress=False)
    return float(jarena.evaluate(agent, arena, jax.random.key(0)).summary()["return_mean"])


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory):
    arena = jarena.build_arena(PENDULUM)
    path = str(tmp_path_factory.mktemp("demos") / "pendulum")
    return arena, path, demonstrations(path, "oracle_pendulum", arena, 50)


def test_bc_clones_the_pendulum_oracle(pendulum):
    """The target: BC's mean eval return is within 90% of the oracle's on the same eval episodes.

    Pendulum returns are negative costs, so 90% of the oracle's performance means a return of at least
    ``oracle / 0.9`` (a cost at most 1/0.9 ~ 1.11 times the oracle's).
    """
    arena, path, oracle = pendulum
    agent = jarena_agents.build_agent("bc", {"dataset": path, "hidden": (64, 64), "total_steps": 4000})
    result = train_and_evaluate(agent, arena, jax.random.key(0), validate_every=0, progress=False)
    cloned = result.evaluation.summary()["return_mean"]
    print(f"pendulum: oracle {oracle:.1f}, bc {cloned:.1f}")
    assert oracle < -100  # a swing-up costs something: the bar is not vacuous
    assert cloned >= oracle / 0.9
    random = jarena.evaluate(jarena_agents.build_agent("random"), arena, jax.random.key(0)).summary()["return_mean"]
    assert random < 3 * oracle  # the eval episodes do need the skill
    assert result.history[-1]["loss"] < 0.5 * result.history[0]["loss"]
    assert all(h["episodes"] == 0 and math.isnan(h["episode_return"]) for h in result.history)  # no env episodes


def test_bc_clones_the_cartpole_oracle_with_discrete_actions(tmp_path):
    arena = jarena.build_arena(CARTPOLE)
    oracle = demonstrations(tmp_path / "cartpole", "oracle_cartpole", arena, 8)
    agent = jarena_agents.build_agent("bc", {"dataset": str(tmp_path / "cartpole"), "hidden": (32, 32),
                                             "total_steps": 600})
    result = train_and_evaluate(agent, arena, jax.random.key(0), validate_every=0, progress=False)
    cloned = result.evaluation.summary()["return_mean"]
    print(f"cartpole: oracle {oracle:.1f}, bc {cloned:.1f}")
    assert cloned >= 0.9 * oracle and oracle == 500.0
    # train mode samples from the categorical policy: actions stay in the spec
    _, info = jarena.batch_reset(arena, jax.random.key(1), 16)
    action, _ = agent.act(agent.policy(result.train_state, arena.spec, False), info, jax.random.key(2))
    assert action.shape == (16,) and action.dtype == jnp.int32 and bool(jnp.all((action == 0) | (action == 1)))


def test_gaussian_policy_and_action_chunks_train(pendulum):
    arena, path, _ = pendulum
    agent = jarena_agents.build_agent("bc", {"dataset": path, "policy": "gaussian", "chunk": 4, "hidden": (32,),
                                             "batch_size": 64, "nll_beta": 1.0})
    state = jax.jit(agent.init_training, static_argnums=1)(jax.random.key(0), arena)
    state, metrics = jax.jit(agent.train, static_argnums=(1, 2))(state, arena, 300)
    losses = np.asarray(metrics["loss"])
    assert losses.shape == (300,) and np.all(np.isfinite(losses)) and losses[-50:].mean() < losses[:50].mean() - 0.1
    kernel = state.params["params"]["Dense_1"]["kernel"]
    assert kernel.shape == (32, 4 * 2)  # K = 4 steps of (mean, log std)
    _, info = jarena.batch_reset(arena, jax.random.key(1), 32)
    for deterministic in (True, False):
        action, _ = agent.act(agent.policy(state, arena.spec, deterministic), info, jax.random.key(2))
        assert action.shape == (32, 1) and bool(jnp.all(jnp.abs(action) <= 2.0))
    eval_action, _ = agent.act(agent.policy(state, arena.spec, True), info, jax.random.key(3))
    np.testing.assert_array_equal(eval_action, agent.act(agent.policy(state, arena.spec, True), info,
                                                         jax.random.key(4))[0])  # eval acts with the mean


def test_windows_hold_consecutive_steps_of_one_trajectory(pendulum):
    arena, path, _ = pendulum
    host = read_dataset(path, arena, chunk=5)
    data, lengths = jax.tree_util.tree_map(jnp.asarray, host["data"]), jnp.asarray(host["lengths"])
    key = jax.random.key(7)
    observation, goal, actions = jax.jit(sample, static_argnums=(3, 4))(data, lengths, key, 16, 5)
    assert observation["state"].shape == (16, 3) and actions.shape == (16, 5, 1) and goal == {}
    rank, step, _ = jarena.data.loader.draw_indices(key, lengths, "window", 16, 5)
    dataset = TrajectoryDataset(path)
    for i in range(16):
        trajectory = dataset.get_trajectory(int(rank[i, 0]))
        t = int(step[i, 0])
        np.testing.assert_array_equal(observation["state"][i], trajectory["observation"]["state"][t])
        np.testing.assert_array_equal(actions[i], trajectory["action"]["action"][t:t + 5])


def test_observation_statistics_and_flattening_match_the_arena(pendulum):
    arena, path, _ = pendulum
    host = read_dataset(path, arena, chunk=1)
    states = np.concatenate([t["observation"]["state"] for t in TrajectoryDataset(path)])
    np.testing.assert_allclose(host["mean"], states.mean(0), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(host["var"], states.var(0), rtol=1e-4)
    _, info = jarena.batch_reset(arena, jax.random.key(0), 4)
    np.testing.assert_array_equal(flatten(info.observation, {}), networks.flatten_observation(info))


def test_to_unit_scales_box_bounds_to_minus_one_one():
    spec = Box(low=np.array([0.0, -1.0]), high=np.array([1.0, 3.0]), shape=(2,))
    np.testing.assert_allclose(to_unit(spec, jnp.array([[0.0, -1.0], [1.0, 3.0], [0.5, 1.0]])),
                               [[-1, -1], [1, 1], [0, 0]])


def test_same_key_same_run_and_seeds_vmap(pendulum):
    arena, path, _ = pendulum
    agent = jarena_agents.build_agent("bc", {"dataset": path, "hidden": (16,), "batch_size": 32})

    init = jax.jit(lambda key: agent.init_training(key, arena))  # reads the dataset through a host callback
    train = jax.jit(lambda state: agent.train(state, arena, 5)[0].params)  # in the persistent compilation cache
    keys = jax.random.split(jax.random.key(0), 2)
    batched = jax.jit(jax.vmap(train))(jax.jit(jax.vmap(init))(keys))

    def run(key):
        return train(init(key))

    alone = run(keys[1])
    for a, b in zip(jax.tree_util.tree_leaves(alone), jax.tree_util.tree_leaves(batched), strict=True):
        np.testing.assert_allclose(a, b[1], rtol=1e-5, atol=1e-6)
        assert not np.allclose(b[0], b[1])
    for a, b in zip(jax.tree_util.tree_leaves(run(keys[1])), jax.tree_util.tree_leaves(alone), strict=True):
        np.testing.assert_array_equal(a, b)


def test_checkpoint_round_trip_and_resume(pendulum, tmp_path):
    arena, path, _ = pendulum
    agent = jarena_agents.build_agent("bc", {"dataset": path, "hidden": (16,), "batch_size": 32})
    train = jax.jit(agent.train, static_argnums=(1, 2))
    state, _ = train(jax.jit(agent.init_training, static_argnums=1)(jax.random.key(3), arena), arena, 3)
    agent.save(tmp_path / "ckpt", state, step=3)
    loaded = agent.load(tmp_path / "ckpt", arena)
    a, _ = train(state, arena, 2)
    b, _ = train(loaded, arena, 2)
    for x, y in zip(jax.tree_util.tree_leaves(a.params), jax.tree_util.tree_leaves(b.params), strict=True):
        np.testing.assert_array_equal(x, y)


def test_clear_errors(pendulum, tmp_path):
    arena, path, _ = pendulum
    with pytest.raises(ValueError, match="set its config key dataset=PATH"):
        jarena_agents.build_agent("bc").init_training(jax.random.key(0), arena)
    with pytest.raises(DatasetError, match="no dataset at"):
        jarena_agents.build_agent("bc", {"dataset": str(tmp_path / "none")}).init_training(jax.random.key(0), arena)
    with pytest.raises(DatasetError, match="does not fit arena 'classic-cartpole-balance'"):
        jarena_agents.build_agent("bc", {"dataset": path}).init_training(jax.random.key(0),
                                                                          jarena.build_arena(CARTPOLE))
    with pytest.raises(DatasetError, match="chunk=500 needs trajectories of at least 500 steps"):
        jarena_agents.build_agent("bc", {"dataset": path, "chunk": 500}).init_training(jax.random.key(0), arena)
    with pytest.raises(jarena_agents.ConfigError, match=r"unknown policy 'gmm'; valid policies: \['deterministic', "
                                                        r"'gaussian', 'mixture'\]"):
        jarena_agents.build_agent("bc", {"policy": "gmm"})
    with pytest.raises(jarena_agents.ConfigError, match="policy 'gaussian' does not support Discrete actions"):
        gaussian = jarena_agents.build_agent("bc", {"policy": "gaussian"})
        gaussian.init(jax.random.key(0), jarena.build_arena(CARTPOLE).spec, 1)
    with pytest.raises(jarena_agents.ConfigError, match="'chunk' of agent 'bc' must be >= 1"):
        jarena_agents.build_agent("bc", {"chunk": 0})
    assert "bc" in jarena_agents.list_agents("imitation")
