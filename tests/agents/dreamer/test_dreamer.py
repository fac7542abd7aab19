"""Dreamer: acting filters a belief and samples the actor, training runs the model and the actor-critic in
imagination online and resumes bit for bit, and a small Dreamer learns to swing the pendulum up."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.runners.evaluate import evaluate
from jarena_agents.dreamer.agent import bounded_normal

TINY = dict(num_arenas=2, rollout_length=5, train_steps=2, batch_size=2, sequence_length=4, buffer_size=2 * 40,
            learning_starts=20, total_steps=40, deter=8, stoch=2, classes=3, hidden=8, layers=1, bins=11,
            imagination_horizon=3)
# The tiny agent's programs run a few small steps: XLA's CPU code optimisation costs far more than it saves there
# (its training chunk: 16 s -> 6 s to compile). The learning test compiles as usual.
FAST_COMPILE = {"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
                "xla_cpu_use_fusion_emitters": False}


@pytest.fixture(scope="module")
def pendulum():
    return jarena.build_arena("classic|domain:pendulum")


@pytest.fixture(scope="module")
def agent():
    return jarena_agents.build_agent("dreamer", TINY)


@pytest.fixture(scope="module")
def compiled(agent):
    """The tiny agent's jitted ``init_training`` and ``train``, shared by the tests (one compilation each)."""
    return (jax.jit(agent.init_training, static_argnums=1, compiler_options=FAST_COMPILE),
            jax.jit(agent.train, static_argnums=(1, 2), compiler_options=FAST_COMPILE))


def test_the_bounded_normal_stays_in_its_ranges():
    dist = bounded_normal(jnp.array([[100.0, -100.0], [-100.0, 100.0]]))
    np.testing.assert_allclose(dist.mode()[:, 0], [1.0, -1.0], atol=1e-6)
    np.testing.assert_allclose(jnp.exp(dist.log_std[:, 0]), [0.1, 1.0], atol=1e-6)
    samples = dist.unit(dist.sample(jax.random.key(0)))
    assert bool(jnp.all(jnp.abs(samples) <= 1.0))


def test_acting_and_a_policy_for_any_batch(agent, compiled, pendulum):
    # init, reset and act each as one program: op by op they compile hundreds of small ones
    state = jax.jit(lambda key: agent.init(key, pendulum.spec, 3), compiler_options=FAST_COMPILE)(jax.random.key(0))
    _, info = jax.jit(lambda key: jarena.batch_reset(pendulum, key, 3))(jax.random.key(1))
    action, state = jax.jit(agent.act, compiler_options=FAST_COMPILE)(state, info, jax.random.key(2))
    assert action.shape == (3, 1) and bool(jnp.all(jnp.abs(action) <= 2.0))
    np.testing.assert_allclose(state.memory.previous_action, action)  # the model sees the arena's actions
    init, _ = compiled
    ts = init(jax.random.key(0), pendulum)
    policy = agent.policy(ts, pendulum.spec, True)
    result = evaluate(agent, pendulum, jax.random.key(0), agent_state=policy, episodes=np.arange(3), max_steps=5)
    assert np.all(np.isfinite(result.returns))
    act_two = jax.jit(lambda policy, info, key: agent.act(agent.batch_state(policy, 2),
                                                         jax.tree_util.tree_map(lambda x: x[:2], info), key)[0],
                      compiler_options=FAST_COMPILE)
    a, b = act_two(policy, info, jax.random.key(3)), act_two(policy, info, jax.random.key(4))
    np.testing.assert_array_equal(a, b)  # deterministic: the actor's mode


def test_training_trains_model_actor_and_critic_and_resumes_bit_for_bit(compiled, pendulum):
    init, train = compiled
    ts = init(jax.random.key(0), pendulum)
    whole, metrics = train(ts, pendulum, 4)
    assert float(metrics["model_loss"][0]) == 0.0 and np.all(np.asarray(metrics["model_loss"][1:]) > 0)
    for part in ("model", "actor", "critic", "slow_critic"):
        before = jax.tree_util.tree_leaves(getattr(ts.learner, part))
        after = jax.tree_util.tree_leaves(getattr(whole.learner, part))
        assert any(not np.allclose(x, y) for x, y in zip(before, after, strict=True)), part
    half, _ = train(init(jax.random.key(0), pendulum), pendulum, 2)
    resumed, _ = train(half, pendulum, 2)
    data = lambda x: jax.random.key_data(x) if jnp.issubdtype(x.dtype, jax.dtypes.prng_key) else x
    for a, b in zip(jax.tree_util.tree_leaves(whole), jax.tree_util.tree_leaves(resumed), strict=True):
        np.testing.assert_array_equal(data(a), data(b))


def test_dreamer_learns_to_swing_the_pendulum_up():
    """4,000 decisions (16,000 control steps, action repeat 4) of a small Dreamer, 50 gradient steps per 200
    decisions with a 10-step imagination: the actor's mode swings the pendulum up better than uniform random
    actions, which get about -1,250 on the same episodes (seeds 0-2 gave -324 to -578)."""
    arena = jarena.build_arena("classic|domain:pendulum,action:repeat(4)")
    config = dict(num_arenas=8, rollout_length=25, train_steps=50, batch_size=16, sequence_length=25,
                  buffer_size=8 * 2000, learning_starts=400, total_steps=4000, deter=64, stoch=8, classes=8,
                  hidden=64, layers=1, model_learning_rate=1e-3, actor_learning_rate=1e-4, critic_learning_rate=1e-4,
                  discount=0.99, imagination_horizon=10)
    agent = jarena_agents.build_agent("dreamer", config)
    ts = jax.jit(agent.init_training, static_argnums=1)(jax.random.key(0), arena)
    ts, metrics = jax.jit(agent.train, static_argnums=(1, 2))(ts, arena, agent.settings.num_updates)
    episodes = np.arange(8)
    learned = evaluate(agent, arena, jax.random.key(1), agent_state=agent.policy(ts, arena.spec, True),
                       episodes=episodes).summary()["return_mean"]
    random = evaluate(jarena_agents.build_agent("random"), arena, jax.random.key(1),
                      episodes=episodes).summary()["return_mean"]
    assert random < -1000 and learned > -800, (learned, random)
