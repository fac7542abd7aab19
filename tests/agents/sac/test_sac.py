import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.training import train_and_evaluate
from jarena_agents.sac.agent import Actor

# A small, fast configuration for the mechanics tests (not for learning): 2 arenas, 1 gradient step per
# update from the 10th update on. The tests share its jitted functions (one compilation each).
TINY = {"num_arenas": 2, "hidden": [16, 16], "batch_size": 16, "buffer_size": 512, "learning_starts": 20, "utd": 0.5}
AGENT = jarena_agents.build_agent("sac", TINY)
init_training = jax.jit(AGENT.init_training, static_argnums=1)
train = jax.jit(AGENT.train, static_argnums=(1, 2))
CHUNK = 8


def raw_leaves(tree):
    return [jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x
            for x in jax.tree_util.tree_leaves(tree)]


@pytest.fixture(scope="module")
def pendulum():
    return jarena.build_arena("classic|domain:pendulum")


def test_sac_learns_pendulum_swingup(pendulum):
    # Random actions score about -1200; these settings reach about -145 on every seed tried (0-13).
    agent = jarena_agents.build_agent("sac", {"hidden": [64, 64], "total_steps": 8000, "learning_starts": 1000,
                                              "actor_lr": 1e-3, "critic_lr": 1e-3, "alpha_lr": 1e-3})
    result = train_and_evaluate(agent, pendulum, jax.random.key(0), chunk_updates=400, validate_every=0,
                                progress=False)
    returns = [h["episode_return"] for h in result.history]
    assert np.mean(returns[-4:]) > np.mean(returns[:4]) + 500
    assert result.evaluation.summary()["return_mean"] >= -400
    assert result.history[-1]["alpha"] < 0.5  # the temperature was tuned down from 1


def test_train_chunk_under_jit_collects_then_learns(pendulum):
    state = init_training(jax.random.key(0), pendulum)
    after, metrics = train(state, pendulum, CHUNK)  # 16 env steps < learning_starts: random actions, no learning
    assert metrics["episode_return"].shape == metrics["episodes"].shape == (CHUNK,)
    assert int(after.env_steps) == 16 and int(after.update) == 8 and int(after.buffer.count) == 8
    for a, b in zip(jax.tree_util.tree_leaves(state.actor_params), jax.tree_util.tree_leaves(after.actor_params),
                    strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(metrics["critic_loss"], 0.0)
    actions = np.asarray(after.buffer.experience["action"][:8])
    assert actions.min() < -0.5 and actions.max() > 0.5  # uniform over the bounds, not the initial policy

    after, metrics = train(after, pendulum, CHUNK)  # 20 env steps by update 10: from there 1 gradient step each
    assert metrics["critic_loss"][0] == 0 and np.all(metrics["critic_loss"][1:] > 0)
    assert metrics["alpha"][1] == 1.0 and float(after.log_alpha) != 0.0  # autotuned from initial_alpha = 1
    changed = [not np.array_equal(a, b) for a, b in zip(jax.tree_util.tree_leaves(state.critic_params),
                                                        jax.tree_util.tree_leaves(after.critic_params), strict=True)]
    assert all(changed)
    target, online = (jax.tree_util.tree_leaves(after.target_critic_params),
                      jax.tree_util.tree_leaves(after.critic_params))
    assert not np.array_equal(target[0], online[0])  # targets trail the critics (Polyak averaging)


def test_buffer_holds_transitions_across_auto_resets(pendulum):
    # 208 steps of 2 arenas: every arena's first episode is truncated at its 200th step.
    state = init_training(jax.random.key(1), pendulum)
    chunks = []
    for _ in range(26):
        state, metrics = train(state, pendulum, CHUNK)
        chunks.append(metrics)
    metrics = jax.tree_util.tree_map(lambda *x: np.concatenate(x), *chunks)
    assert int(np.sum(metrics["episodes"])) == 2 and int(np.argmax(metrics["episodes"])) == 199
    exp = jax.tree_util.tree_map(np.asarray, state.buffer.experience)
    end = exp["step"][:208] == 199
    np.testing.assert_array_equal(end, exp["truncated"][:208])
    assert end.sum() == 2 and not exp["terminated"].any()  # truncation only: the critic bootstraps there
    same = ~end[:207]
    np.testing.assert_array_equal(exp["next_observation"][:207][same], exp["observation"][1:208][same])
    # at the cut the next observation is the finished episode's last one (info.final), not the reset one
    assert not np.allclose(exp["next_observation"][199], exp["observation"][200])
    cos, sin = exp["next_observation"][199, :, 0], exp["next_observation"][199, :, 1]
    np.testing.assert_allclose(cos**2 + sin**2, 1.0, rtol=1e-5)
    # the recorded episode return is the sum of the stored rewards of that episode
    np.testing.assert_allclose(metrics["episode_return"][199], exp["reward"][:200].sum(0).mean(), rtol=1e-5)


def test_training_is_one_function_of_a_key_and_vmaps_over_seeds(pendulum):
    @jax.jit
    @jax.vmap
    def run(key):
        state, metrics = AGENT.train(AGENT.init_training(key, pendulum), pendulum, 2 * CHUNK)
        return state.actor_params, metrics

    def alone(key):
        state = init_training(key, pendulum)
        state, _ = train(state, pendulum, CHUNK)
        return train(state, pendulum, CHUNK)[0].actor_params

    keys = jax.random.split(jax.random.key(0), 2)
    params, metrics = run(keys)
    assert metrics["critic_loss"].shape == (2, 2 * CHUNK) and np.all(metrics["critic_loss"][:, -1] > 0)
    leaf = jax.tree_util.tree_leaves(params)[0]
    assert leaf.shape[0] == 2 and not np.allclose(leaf[0], leaf[1])
    for i in range(2):
        for a, b in zip(jax.tree_util.tree_leaves(alone(keys[i])), jax.tree_util.tree_leaves(params), strict=True):
            np.testing.assert_allclose(a, b[i], rtol=1e-5, atol=1e-6)  # vmapped seed == the same seed alone
    for a, b in zip(jax.tree_util.tree_leaves(alone(keys[0])), jax.tree_util.tree_leaves(alone(keys[0])), strict=True):
        np.testing.assert_array_equal(a, b)  # same key, bit-identical


def test_policy_acts_in_bounds_and_eval_mode_is_deterministic(pendulum):
    state = init_training(jax.random.key(0), pendulum)
    _, info = jarena.batch_reset(pendulum, jax.random.key(1), 64)
    act = jax.jit(AGENT.act)
    eval_state, train_state = AGENT.policy(state, pendulum.spec, True), AGENT.policy(state, pendulum.spec, False)
    a1, _ = act(eval_state, info, jax.random.key(2))
    a2, _ = act(eval_state, info, jax.random.key(3))
    np.testing.assert_array_equal(a1, a2)
    mean, _ = Actor(1, (16, 16)).apply(state.actor_params, info.observation["state"])
    np.testing.assert_allclose(a1, 2.0 * np.tanh(mean), rtol=1e-5, atol=1e-6)  # tanh of the mean, scaled to [-2, 2]
    s1, _ = act(train_state, info, jax.random.key(2))
    s2, _ = act(train_state, info, jax.random.key(3))
    assert s1.shape == (64, 1) and not np.allclose(s1, s2)
    assert bool(jnp.all(jnp.abs(s1) <= 2.0))


def test_sac_rejects_discrete_actions_and_bad_configs():
    cartpole = jarena.build_arena("classic|domain:cartpole")
    with pytest.raises(TypeError, match="only continuous actions.*Discrete"):
        AGENT.init_training(jax.random.key(0), cartpole)
    with pytest.raises(ValueError, match="gradient steps per update.*positive integer"):
        jarena_agents.build_agent("sac", {"num_arenas": 3, "utd": 0.5})
    rounded = "sac: buffer_size=1000 is not a multiple of num_arenas=3; using buffer_size=999"
    with pytest.warns(UserWarning, match=rounded):
        assert jarena_agents.build_agent("sac", {"num_arenas": 3, "buffer_size": 1000}).settings.buffer_size == 999
    with pytest.raises(jarena_agents.ConfigError, match="unknown config key"):
        jarena_agents.build_agent("sac", {"lr": 1e-3})
    assert "sac" in jarena_agents.list_agents("trainable")


def test_interrupted_and_resumed_run_equals_uninterrupted(pendulum, tmp_path):
    agent = jarena_agents.build_agent("sac", TINY | {"total_steps": 6 * CHUNK * 2})
    kwargs = dict(chunk_updates=CHUNK, validate_every=0, checkpoint_every=1, progress=False)
    whole = train_and_evaluate(agent, pendulum, jax.random.key(3), run_dir=tmp_path / "whole", **kwargs)
    partial = train_and_evaluate(agent, pendulum, jax.random.key(3), run_dir=tmp_path / "cut", stop_after_chunks=2,
                                 **kwargs)
    assert partial.evaluation is None and len(partial.history) == 2
    resumed = train_and_evaluate(agent, pendulum, jax.random.key(3), run_dir=tmp_path / "cut", **kwargs)
    assert len(resumed.history) == len(whole.history) == 6
    assert int(resumed.train_state.buffer.count) == 6 * CHUNK  # the buffer came back from the checkpoint
    for a, b in zip(raw_leaves(whole.train_state), raw_leaves(resumed.train_state), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(whole.evaluation.returns, resumed.evaluation.returns)
    assert [h["critic_loss"] for h in whole.history] == [h["critic_loss"] for h in resumed.history]
