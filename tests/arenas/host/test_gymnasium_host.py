"""Gymnasium envs as host arenas: the same physics as jarena's own arenas from the same states, episode ids
mapped to seeds, the host auto-reset, open batches, clear errors, and agents that train and evaluate on them."""

import shutil

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.arenas.host import HostPhysics, episode_seed, from_gymnasium
from jarena.building.grammar import ArenaStringError
from jarena.core.agent import AgentArenaMismatch
from jarena.data import TrajectoryDataset, configs_for
from jarena.training import train_and_evaluate
from jarena_agents.config import ConfigError


@pytest.fixture(scope="module")
def host_cartpole():
    return jarena.build_arena("gym|id:CartPole-v1")


def test_specs_come_from_the_spaces(host_cartpole):
    env = gymnasium.make("CartPole-v1")
    spec = host_cartpole.observation_spec.spaces["state"]
    np.testing.assert_array_equal(spec.low, env.observation_space.low)
    np.testing.assert_array_equal(spec.high, env.observation_space.high)
    assert spec.dtype == np.float32 and host_cartpole.action_spec == jarena.Discrete(2)
    assert host_cartpole.max_episode_steps == 500 and host_cartpole.auto_reset == "host"
    pendulum = jarena.build_arena("gym|id:Pendulum-v1(g=9.81)")
    assert pendulum.action_spec == jarena.Box(-2.0, 2.0, (1,))


def test_cartpole_steps_as_classic_cartpole_from_the_same_states(cartpole):
    """Gymnasium's CartPole-v1 behind the host arena and jarena's ``classic|domain:cartpole``: each step starts
    both from the classic arena's state (written into the Gymnasium env) and they agree."""
    made = []

    def factory():
        made.append(gymnasium.make("CartPole-v1"))
        return made[-1]

    host = from_gymnasium(factory)
    num = 8
    key = jax.random.key(3)
    c_state, c_info = jax.jit(lambda k: jarena.batch_reset(cartpole, k, num))(key)
    h_state, _ = jax.jit(lambda k: jarena.batch_reset(host, k, num))(key)
    envs = made[-num:]
    c_step = jax.jit(lambda s, a: jarena.batch_step(cartpole, s, a, reset_done=False))
    h_step = jax.jit(lambda s, a: jarena.batch_step(host, s, a, reset_done=False))
    live = np.ones(num, bool)
    compared = 0
    for t in range(300):
        for env, x in zip(envs, np.asarray(c_info.observation["state"]), strict=True):
            env.unwrapped.state = x.astype(np.float64)
        action = jax.random.bernoulli(jax.random.fold_in(key, t), 0.5, (num,)).astype(jnp.int32)
        c_state, c_info = c_step(c_state, action)
        h_state, h_info = h_step(h_state, action)
        np.testing.assert_allclose(np.asarray(h_info.observation["state"])[live],
                                   np.asarray(c_info.observation["state"])[live], rtol=1e-5, atol=1e-6)
        np.testing.assert_array_equal(np.asarray(h_info.reward)[live], np.asarray(c_info.reward)[live])
        np.testing.assert_array_equal(np.asarray(h_info.terminated)[live], np.asarray(c_info.terminated)[live])
        compared += live.sum()
        live &= ~np.asarray(c_info.done)
        if not live.any():
            break
    assert not live.any() and compared > 50  # every episode ran to its end


def test_episode_ids_map_to_seeds_at_any_batch_size_and_order(host_cartpole):
    """Episode i starts from ``reset(seed=episode_seed(i))`` of the Gymnasium env, whatever batch it is in."""
    env = gymnasium.make("CartPole-v1")
    for ids in ([0, 1, 2], [5, 2, 0, 9, 1]):
        _, info = jax.jit(lambda e: jarena.batch_reset(host_cartpole, None, len(ids), episodes=e))(jnp.array(ids))
        for i, obs in zip(ids, np.asarray(info.observation["state"]), strict=True):
            np.testing.assert_array_equal(obs, env.reset(seed=episode_seed(i))[0])
    assert len({episode_seed(i) for i in range(100)}) == 100


def test_auto_reset_restarts_only_finished_simulators_with_the_next_episodes_seed(host_cartpole):
    env = gymnasium.make("CartPole-v1")
    state, info = jax.jit(lambda k: jarena.batch_reset(host_cartpole, k, 4))(jax.random.key(0))
    step = jax.jit(lambda s, a: jarena.batch_step(host_cartpole, s, a))
    restarts = 0
    for _ in range(60):
        before = np.asarray(info.observation["state"])
        state, info = step(state, jnp.zeros(4, jnp.int32))  # always left: episodes end in ~10 steps
        done = np.asarray(info.done)
        for i in np.flatnonzero(done):
            np.testing.assert_array_equal(np.asarray(info.observation["state"])[i],
                                          env.reset(seed=episode_seed(int(info.episode[i])))[0])
            assert np.asarray(info.final.observation["state"])[i][2] > 0.2  # pushed left, the pole fell right
            assert int(info.step[i]) == 0 and info.reward[i] == 1.0
        for i in np.flatnonzero(~done):  # the others stepped on from where they were
            assert abs(np.asarray(info.observation["state"])[i][0] - before[i][0]) < 0.1
        restarts += done.sum()
    assert restarts >= 12


def test_a_training_batch_and_validation_batches_stay_open_and_a_closed_one_is_named():
    arena = from_gymnasium("CartPole-v1", max_batches=2)
    reset = jax.jit(lambda k: jarena.batch_reset(arena, k, 3))
    step = jax.jit(lambda s, a: jarena.batch_step(arena, s, a))
    train, _ = reset(jax.random.key(0))
    for i in range(4):  # a validation batch between training steps never closes the training batch
        val, _ = reset(jax.random.key(i + 1))
        val, _ = step(val, jnp.zeros(3, jnp.int32))
        train, _ = step(train, jnp.ones(3, jnp.int32))
    reset(jax.random.key(9))  # a third batch closes the least recently used: the last validation batch
    with pytest.raises(Exception, match="batch .* was closed: at most max_batches=2"):
        jax.block_until_ready(step(val, jnp.zeros(3, jnp.int32)))
    jax.block_until_ready(step(train, jnp.zeros(3, jnp.int32)))


def test_states_from_elsewhere_and_subsets_are_refused_with_reasons(host_cartpole):
    state, _ = jax.jit(lambda k: jarena.batch_reset(host_cartpole, k, 4))(jax.random.key(0))
    step = jax.jit(lambda s, a: jarena.batch_step(host_cartpole, s, a))
    half = jax.tree_util.tree_map(lambda x: x[:2], state)
    with pytest.raises(Exception, match="steps every arena of its batch together"):
        jax.block_until_ready(step(half, jnp.zeros(2, jnp.int32)))
    stranger = state.replace(physics=state.physics.replace(batch=jnp.full(4, 10**6, jnp.int32)))
    with pytest.raises(Exception, match="never opened in this process"):
        jax.block_until_ready(step(stranger, jnp.zeros(4, jnp.int32)))
    copies = jax.tree_util.tree_map(lambda x: jnp.repeat(x[:1], 4, axis=0), state)
    with pytest.raises(Exception, match="several copies of one arena .* share one simulator"):
        jax.block_until_ready(step(copies, jnp.zeros(4, jnp.int32)))
    # a permutation of a batch's arenas steps each arena with its own action
    reset = jax.jit(lambda e: jarena.batch_reset(host_cartpole, None, 4, episodes=e))
    action = jnp.array([0, 1, 1, 0], jnp.int32)
    order = jnp.array([2, 0, 3, 1])
    direct, _ = reset(jnp.arange(4))
    shuffled, _ = reset(jnp.arange(4))
    shuffled = jax.tree_util.tree_map(lambda x: x[order], shuffled)
    for _ in range(3):
        direct, want = step(direct, action)
        shuffled, got = step(shuffled, action[order])
        np.testing.assert_array_equal(got.observation["state"], want.observation["state"][order])
    assert isinstance(direct.physics, HostPhysics)


def test_bad_input_names_the_choices():
    with pytest.raises(ArenaStringError, match="unknown Gymnasium env id 'NoSuchEnv-v0'"):
        jarena.build_arena("gym|id:NoSuchEnv-v0")
    with pytest.raises(ArenaStringError, match="vectorization.*sync.*async"):
        jarena.build_arena("gym|id:CartPole-v1,vectorization:threads")
    with pytest.raises(TypeError, match="MultiDiscrete spaces are not supported; supported: Box, Discrete, Dict"):
        from_gymnasium(lambda: _Multi())
    with pytest.raises(ValueError, match="max_batches must be at least 1, got 0"):
        from_gymnasium("CartPole-v1", max_batches=0)
    with pytest.raises(ValueError, match="auto_reset 'host' is for dynamics whose simulator lives outside JAX"):
        jarena.build_arena("classic|domain:cartpole,auto_reset:host")


class _Multi(gymnasium.Env):
    observation_space = gymnasium.spaces.Box(-1, 1, (2,))
    action_space = gymnasium.spaces.MultiDiscrete([2, 3])


def test_planners_and_oracles_are_refused_agents_that_act_on_observations_run(host_cartpole):
    with pytest.raises(ConfigError, match="cannot plan in arena 'gym.id:Pendulum-v1': its simulator runs on the host"):
        jarena_agents.build_agent("cem", {"arena": "gym|id:Pendulum-v1"})
    with pytest.raises(AgentArenaMismatch, match="made for arenas with 'cartpole' dynamics"):
        jarena.evaluate(jarena_agents.build_agent("oracle_cartpole"), host_cartpole, episodes=[0, 1])
    state, _ = host_cartpole.reset(jax.random.key(0))
    with pytest.raises(TypeError, match="runs its simulator on the host .* cannot be copied or rolled forward"):
        host_cartpole.privileged(state)
    result = jarena.evaluate(jarena_agents.build_agent("random"), host_cartpole, episodes=range(6))
    lengths = result.lengths
    assert np.all(lengths > 5) and np.all(lengths < 100) and np.array_equal(result.returns, lengths)
    again = jarena.evaluate(jarena_agents.build_agent("random"), host_cartpole, episodes=range(6))
    np.testing.assert_array_equal(result.returns, again.returns)  # same key, same episodes, same result


def test_ppo_trains_on_gymnasium_cartpole(host_cartpole):
    config = {**jarena.retrieve_config("ppo", host_cartpole), "total_steps": 100_000}
    result = train_and_evaluate(jarena_agents.build_agent("ppo", config), host_cartpole, jax.random.key(0),
                                validate_every=0, progress=False)
    returns = [h["episode_return"] for h in result.history]
    assert returns[-1] > 3 * returns[0]
    assert result.evaluation.summary()["return_mean"] > 200  # random: ~22


@pytest.fixture
def unoptimised_compiles():
    """XLA optimises less while the test runs. A host arena's programs hold its callbacks' addresses, so the
    persistent compilation cache never holds them and every run compiles them again: for short runs the
    compiler's optimisation passes cost more than they save (Dreamer's training program: 23 s -> 10 s to
    compile on a CPU, the same evaluation)."""
    previous = jax.config.read("jax_disable_most_optimizations")
    jax.config.update("jax_disable_most_optimizations", True)
    yield
    jax.config.update("jax_disable_most_optimizations", previous)


@pytest.mark.usefixtures("unoptimised_compiles")
@pytest.mark.parametrize("agent_name,config", [
    ("sac", {"total_steps": 600, "learning_starts": 200, "num_arenas": 2, "batch_size": 32, "hidden": [16, 16]}),
    ("dreamer", {"total_steps": 400, "learning_starts": 200, "num_arenas": 2, "rollout_length": 50,
                 "train_steps": 2, "batch_size": 4, "sequence_length": 8, "buffer_size": 400, "deter": 16,
                 "stoch": 4, "classes": 4, "hidden": 16, "layers": 1, "imagination_horizon": 3}),
])
def test_off_policy_and_world_model_agents_train_and_evaluate_on_a_host_arena(agent_name, config):
    arena = jarena.build_arena("gym|id:Pendulum-v1,eval_episodes:2,val_episodes:2")
    agent = jarena_agents.build_agent(agent_name, config)
    result = train_and_evaluate(agent, arena, jax.random.key(0), validations=1, progress=False)
    summary = result.evaluation.summary()
    assert summary["episodes"] == 2 and summary["length_mean"] == 200
    assert -2000 < summary["return_mean"] < 0  # pendulum's reward is in [-16.3, 0] per step


def test_collect_and_bc_from_a_host_arena(host_cartpole, tmp_path):
    path = str(tmp_path / "cartpole")
    with TrajectoryDataset(path, "w", **configs_for(host_cartpole)) as dataset:
        stored = jarena.collect(jarena_agents.build_agent("random"), host_cartpole, dataset, 4,
                                key=jax.random.key(0), progress=False)
    assert len(stored) == 4 and TrajectoryDataset(path).num_trajectories() == 4
    bc = jarena_agents.build_agent("bc", {"dataset": path, "total_steps": 20, "hidden": (8,)})
    result = train_and_evaluate(bc, host_cartpole, jax.random.key(1), validations=1, progress=False)
    assert result.evaluation.summary()["episodes"] == 100


def test_async_workers_give_the_same_episodes_as_sync():
    sync = from_gymnasium("CartPole-v1")
    spawned = from_gymnasium("CartPole-v1", vectorization="async")
    ids = jnp.arange(3)
    results = []
    for arena in (sync, spawned):
        state, info = jax.jit(lambda e: jarena.batch_reset(arena, None, 3, episodes=e))(ids)  # noqa: B023
        step = jax.jit(lambda s, a: jarena.batch_step(arena, s, a))  # noqa: B023
        for t in range(20):
            state, info = step(state, jnp.full(3, t % 2, jnp.int32))
        results.append(np.asarray(info.observation["state"]))
    np.testing.assert_array_equal(*results)


def test_dict_and_image_spaces_become_observation_keys_and_odd_spaces_are_refused():
    from gymnasium import spaces

    from jarena.arenas.host.gymnasium import action_spec, observation_spec
    spec, key = observation_spec(spaces.Dict({"joints": spaces.Box(-1, 1, (3,), np.float64),
                                              "mode": spaces.Discrete(4)}))
    assert key is None and spec.spaces["joints"] == jarena.Box(-1, 1, (3,), jnp.float32)
    assert spec.spaces["mode"] == jarena.Discrete(4)
    spec, key = observation_spec(spaces.Box(0, 255, (8, 8, 3), np.uint8))
    assert key == "pixels" and spec.spaces["pixels"].dtype == np.uint8
    assert observation_spec(spaces.Box(-1, 1, (2,), np.int64))[0].spaces["state"].dtype == np.int32
    with pytest.raises(TypeError, match="Discrete spaces must start at 0, got start=1"):
        action_spec(spaces.Discrete(3, start=1))
    with pytest.raises(TypeError, match="Box of dtype bool is not supported"):
        observation_spec(spaces.Box(0, 1, (2,), bool))


@pytest.mark.usefixtures("unoptimised_compiles")
def test_a_resumed_run_on_a_host_arena_starts_new_episodes_in_this_process(tmp_path, capsys):
    """A checkpoint holds handles on the simulators of the process that wrote it, not their state: the resumed
    run takes its arena states and infos from its own reset, and keeps everything else from the checkpoint."""
    from jarena.core.types import ArenaState, Info
    from jarena.training import fresh_episodes

    arena = jarena.build_arena("gym|id:CartPole-v1,eval_episodes:2,val_episodes:2")
    agent = jarena_agents.build_agent("ppo", {**jarena.retrieve_config("ppo", arena), "total_steps": 4096})
    init = jax.jit(agent.init_training, static_argnums=1)
    restored, fresh = init(jax.random.key(0), arena), init(jax.random.key(1), arena)
    merged = fresh_episodes(restored, fresh)
    is_episode = lambda x: isinstance(x, ArenaState | Info)  # noqa: E731
    episodes = [x for x in jax.tree_util.tree_leaves(merged, is_leaf=is_episode) if is_episode(x)]
    assert episodes  # PPO's train state holds its arenas' states
    for got, want in zip(jax.tree_util.tree_leaves(episodes), jax.tree_util.tree_leaves(
            [x for x in jax.tree_util.tree_leaves(fresh, is_leaf=is_episode) if is_episode(x)]), strict=True):
        np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(jax.tree_util.tree_leaves(merged.params)[0],
                                  jax.tree_util.tree_leaves(restored.params)[0])

    def run():
        return train_and_evaluate(agent, arena, jax.random.key(0), run_dir=tmp_path, checkpoint_every=1,
                                  validations=1, progress=False)

    first = run()
    latest = max(int(p.name) for p in (tmp_path / "checkpoints").iterdir() if p.name.isdigit())
    for step in (latest, latest - 1):  # as if the process had died two chunks before the end
        shutil.rmtree(tmp_path / "checkpoints" / str(step))
    resumed = run()
    out = capsys.readouterr().out
    assert "starts new episodes" in out and "resuming from step" in out
    assert len(resumed.history) == len(first.history)
    assert resumed.evaluation.summary()["episodes"] == 2
