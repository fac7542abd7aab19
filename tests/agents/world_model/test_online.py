"""Online world-model agents' action repeat: a config's ``action_repeat`` trains and acts as the arena's own
``action:repeat(k)`` tool does, while the agent runs on the arena as given, counted in its environment steps."""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct

import jarena
import jarena_agents
from jarena.runners.evaluate import evaluate
from jarena_agents.world_model import online

TINY = dict(num_arenas=2, rollout_length=5, train_steps=2, batch_size=2, sequence_length=4, buffer_size=2 * 40,
            total_steps=40, deter=8, stoch=2, classes=3, hidden=8, layers=1, bins=11, imagination_horizon=3)
FAST_COMPILE = {"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
                "xla_cpu_use_fusion_emitters": False}


def test_the_schedule_counts_environment_steps_and_the_replay_ratio_counts_decisions():
    cfg = jarena_agents.build_agent("dreamer", dict(TINY, action_repeat=2, replay_ratio=8.0)).settings
    assert cfg.decisions_per_update == 10 and cfg.steps_per_update == 20
    assert cfg.gradient_steps == 10  # 8 replayed steps per decision, batches of 2 x 4
    assert cfg.num_updates == 2  # 40 environment steps


def test_acting_decides_every_kth_step_and_holds_the_action_in_between():
    spec = jarena.build_arena("classic|domain:pendulum").spec.action

    def decide(memory, info):
        action = info.step.astype(jnp.float32)[:, None] + 0.5
        return action, memory.replace(previous_action=action)

    @struct.dataclass
    class Memory:
        previous_action: jax.Array

    memory = Memory(jnp.zeros((2, 1), jnp.float32))
    actions = []
    for step in range(6):
        info = SimpleNamespace(step=jnp.array([step, step + 1], jnp.int32))  # two arenas, out of phase
        action, memory = online.hold_between_decisions(3, spec, info, memory, decide)
        actions.append(np.asarray(action)[:, 0])
    # arena 0 decides at steps 0 and 3, arena 1 (a step ahead) at its steps 3 and 6 (loop steps 2 and 5)
    np.testing.assert_array_equal(np.array(actions)[:, 0], [0.5, 0.5, 0.5, 3.5, 3.5, 3.5])
    np.testing.assert_array_equal(np.array(actions)[:, 1], [0.0, 0.0, 3.5, 3.5, 3.5, 6.5])


@pytest.mark.parametrize("name", ["dreamer"])
def test_the_configs_action_repeat_trains_and_acts_as_the_arenas_repeat_tool(name):
    plain = jarena.build_arena("classic|domain:pendulum")
    repeating = jarena.build_arena("classic|domain:pendulum,action:repeat(2)")
    held = jarena_agents.build_agent(name, dict(TINY, action_repeat=2, learning_starts=40))
    tool = jarena_agents.build_agent(name, dict(TINY, learning_starts=20))

    def run(agent, arena):
        ts = jax.jit(agent.init_training, static_argnums=1, compiler_options=FAST_COMPILE)(jax.random.key(0), arena)
        ts, metrics = jax.jit(agent.train, static_argnums=(1, 2), compiler_options=FAST_COMPILE)(ts, arena, 3)
        return ts, metrics

    held_ts, held_metrics = run(held, plain)
    tool_ts, tool_metrics = run(tool, repeating)
    assert float(held_metrics["model_loss"][-1]) > 0.0  # it trained
    assert int(held_ts.env_steps) == 2 * int(tool_ts.env_steps) == 60  # environment steps of the plain arena
    for a, b in zip(jax.tree_util.tree_leaves((held_ts.learner, held_ts.buffer)),
                    jax.tree_util.tree_leaves((tool_ts.learner, tool_ts.buffer)), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
    # acting: on the plain arena the agent holds each action for two steps, as the tool does for it
    episodes = np.arange(3)
    on_plain = evaluate(held, plain, jax.random.key(1), agent_state=held.policy(held_ts, plain.spec), episodes=episodes,
                        max_steps=8)
    on_tool = evaluate(tool, repeating, jax.random.key(1), agent_state=tool.policy(tool_ts, repeating.spec),
                       episodes=episodes, max_steps=4)
    np.testing.assert_allclose(on_plain.returns, on_tool.returns, rtol=1e-5)
    assert np.all(on_plain.lengths == 8) and np.all(on_tool.lengths == 4)


def test_an_arena_that_already_repeats_warns():
    with pytest.warns(UserWarning, match="already repeats"):
        online.decision_arena(jarena.build_arena("classic|domain:pendulum,action:repeat(2)"), 2)
