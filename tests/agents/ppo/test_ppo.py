import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.training import train_and_evaluate


def raw_leaves(tree):
    return [jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x
            for x in jax.tree_util.tree_leaves(tree)]


@pytest.fixture(scope="module")
def cartpole():
    return jarena.build_arena("classic|domain:cartpole,task:balance")


def test_ppo_learns_cartpole(cartpole, tmp_path):
    agent = jarena_agents.build_agent("ppo", {"total_steps": 150_000})
    result = train_and_evaluate(agent, cartpole, jax.random.key(0), validate_every=0, progress=False,
                                run_dir=tmp_path)
    returns = [h["episode_return"] for h in result.history]
    assert returns[-1] > 3 * returns[0]
    assert result.evaluation.summary()["return_mean"] > 300  # random: ~22
    for name in ["config.json", "train.csv", "evaluation.json", "learning_curve.png"]:
        assert (tmp_path / name).is_file()
    from tensorboard_reader import scalars
    logged = scalars(tmp_path / "tensorboard", "train/episode_return")
    assert logged == pytest.approx(returns)


def test_training_is_one_function_of_a_key_and_vmaps_over_seeds(cartpole):
    agent = jarena_agents.build_agent("ppo", {"num_arenas": 4, "rollout_length": 16, "minibatches": 2})

    @jax.jit
    def run(key):
        state, metrics = agent.train(agent.init_training(key, cartpole), cartpole, 3)
        return state.params, metrics

    keys = jax.random.split(jax.random.key(0), 3)
    params, metrics = jax.vmap(run)(keys)
    assert metrics["total"].shape == (3, 3)
    leaf = jax.tree_util.tree_leaves(params)[0]
    assert leaf.shape[0] == 3 and not np.allclose(leaf[0], leaf[1])
    again, _ = run(keys[1])
    for a, b in zip(jax.tree_util.tree_leaves(again), jax.tree_util.tree_leaves(params), strict=True):
        np.testing.assert_allclose(a, b[1], rtol=1e-5, atol=1e-6)  # vmapped seed == the same seed alone
    first, _ = run(keys[0])
    second, _ = run(keys[0])
    for a, b in zip(jax.tree_util.tree_leaves(first), jax.tree_util.tree_leaves(second), strict=True):
        np.testing.assert_array_equal(a, b)  # same key, bit-identical


def test_ppo_continuous_actions_stay_in_bounds():
    arena = jarena.build_arena("classic|domain:pendulum,task:swingup")
    agent = jarena_agents.build_agent("ppo", {"num_arenas": 4, "rollout_length": 16, "minibatches": 2,
                                              "normalize_observations": True})
    state, metrics = jax.jit(lambda k: agent.train(agent.init_training(k, arena), arena, 2))(jax.random.key(0))
    assert all(bool(jnp.all(jnp.isfinite(v))) for v in jax.tree_util.tree_leaves(metrics))
    assert float(state.observation_stats.count) == 2 * 4 * 16
    _, info = jarena.batch_reset(arena, jax.random.key(1), 8)
    action, _ = agent.act(agent.policy(state, arena.spec, False), info, jax.random.key(2))
    assert action.shape == (8, 1) and bool(jnp.all(jnp.abs(action) <= 2.0))


def test_ppo_config_errors():
    with pytest.raises(ValueError, match="divisible by minibatches"):
        jarena_agents.build_agent("ppo", {"num_arenas": 3, "rollout_length": 5, "minibatches": 4})
    with pytest.raises(jarena_agents.ConfigError, match="unknown config key"):
        jarena_agents.build_agent("ppo", {"lr": 1e-3})
    with pytest.raises(TypeError, match="not trainable"):
        train_and_evaluate(jarena_agents.build_agent("random"), jarena.build_arena("classic|domain:cartpole"),
                           jax.random.key(0))


def test_interrupted_and_resumed_run_equals_uninterrupted(cartpole, tmp_path):
    config = {"num_arenas": 4, "rollout_length": 32, "minibatches": 2, "total_steps": 6 * 4 * 32 * 2}
    agent = jarena_agents.build_agent("ppo", config)
    kwargs = dict(chunk_updates=2, validate_every=0, checkpoint_every=1, progress=False)
    whole = train_and_evaluate(agent, cartpole, jax.random.key(3), run_dir=tmp_path / "whole", **kwargs)
    partial = train_and_evaluate(agent, cartpole, jax.random.key(3), run_dir=tmp_path / "cut", stop_after_chunks=2,
                                 **kwargs)
    assert partial.evaluation is None and len(partial.history) == 2
    resumed = train_and_evaluate(agent, cartpole, jax.random.key(3), run_dir=tmp_path / "cut", **kwargs)
    assert len(resumed.history) == len(whole.history) == 6
    for a, b in zip(raw_leaves(whole.train_state), raw_leaves(resumed.train_state), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(whole.evaluation.returns, resumed.evaluation.returns)
    assert [h["episode_return"] for h in whole.history] == [h["episode_return"] for h in resumed.history]


def test_a_run_that_cannot_render_evaluates_without_videos(cartpole, tmp_path, monkeypatch):
    """No OpenGL in the process (mujoco raises a FatalError when it makes a context): the trained agent is
    still evaluated and its results written; only the videos are skipped, with a warning naming the fix."""
    import jarena.render.record as record

    def no_gl(arena):
        def render(*args, **kwargs):
            raise RuntimeError("an OpenGL platform library has not been loaded into this process")
        return render

    monkeypatch.setattr(record, "renderer", no_gl)
    agent = jarena_agents.build_agent("ppo", {"num_arenas": 4, "rollout_length": 16, "minibatches": 2,
                                              "total_steps": 128})
    with pytest.warns(UserWarning, match="evaluating without videos: .*MUJOCO_GL=egl"):
        result = train_and_evaluate(agent, cartpole, jax.random.key(0), validate_every=0, progress=False,
                                    run_dir=tmp_path)
    assert result.evaluation is not None and (tmp_path / "evaluation.json").is_file()
    assert not (tmp_path / "videos").exists()


def test_brax_style_policy_trains_on_box_actions_and_bad_names_are_refused():
    """Brax's PPO network choices: tanh-squashed Gaussian with state-dependent std, swish layers."""
    arena = jarena.build_arena("classic|domain:pendulum,task:swingup")
    agent = jarena_agents.build_agent("ppo", {"num_arenas": 4, "rollout_length": 16, "minibatches": 2,
                                              "total_steps": 128, "box_policy": "tanh_normal",
                                              "activation": "swish"})
    state = agent.init_training(jax.random.key(0), arena)
    state, metrics = jax.jit(agent.train, static_argnums=(1, 2))(state, arena, 2)
    assert all(bool(jnp.all(jnp.isfinite(v))) for v in jax.tree_util.tree_leaves(metrics))
    policy = agent.policy(state, arena.spec, True)
    assert "Dense_1" in policy.params["params"]["actor"] and "log_std" not in policy.params["params"]
    with pytest.raises(ValueError, match="unknown box_policy 'beta'; choose from gaussian, tanh_normal"):
        jarena_agents.build_agent("ppo", {"box_policy": "beta"})
    with pytest.raises(ValueError, match="unknown activation 'gelu'"):
        jarena_agents.build_agent("ppo", {"activation": "gelu"})


def test_segment_gae_equals_whole_rollout_gae_when_one_segment_and_one_step():
    """Brax's scheme (``unroll_length``: GAE per minibatch of segments with the current value network)
    reduces to the PureJaxRL scheme when the segment is the whole rollout and there is one gradient step:
    the current network is then the acting one, and the loss is a mean over the same transitions."""
    arena = jarena.build_arena("classic|domain:pendulum,task:swingup")
    base = {"num_arenas": 4, "rollout_length": 16, "minibatches": 1, "epochs": 1}
    whole = jarena_agents.build_agent("ppo", base)
    segmented = jarena_agents.build_agent("ppo", dict(base, unroll_length=16))
    short = jarena_agents.build_agent("ppo", dict(base, unroll_length=4, minibatches=2, epochs=2))
    results = [jax.jit(lambda k, a=a: a.train(a.init_training(k, arena), arena, 1))(jax.random.key(0))
               for a in (whole, segmented, short)]
    (a, ma), (b, mb), (c, mc) = results
    for x, y in zip(jax.tree_util.tree_leaves(a.params), jax.tree_util.tree_leaves(b.params), strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(ma["total"], mb["total"], rtol=1e-5)
    assert all(bool(jnp.all(jnp.isfinite(v))) for v in jax.tree_util.tree_leaves(mc))
    diff = [float(jnp.max(jnp.abs(x - y))) for x, y in zip(jax.tree_util.tree_leaves(a.params),
                                                           jax.tree_util.tree_leaves(c.params), strict=True)]
    assert max(diff) > 1e-4  # four segments, two epochs: a different update
    with pytest.raises(ValueError, match="unroll_length = 5 must be a positive divisor of rollout_length = 16"):
        jarena_agents.build_agent("ppo", dict(base, unroll_length=5))
    with pytest.raises(ValueError, match="the 4 segments of unroll_length = 8 must be divisible by minibatches = 8"):
        jarena_agents.build_agent("ppo", dict(base, unroll_length=8, minibatches=8, num_arenas=2))
