"""The planner agents: warm start, new-episode resets, per-arena keys, config checks, arena binding."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena_agents import ConfigError
from jarena_agents.planners import arena_model, make_mppi, make_predictive_sampling
from jarena_agents.planners.mppi import MPPIConfig, mppi_improve
from jarena_agents.planners.sampling import shift_plan

PENDULUM = "classic|domain:pendulum"


@pytest.fixture(scope="module")
def arena():
    return jarena.build_arena(PENDULUM)


def _batch(arena, n, steps=1):
    """B = n arenas after ``steps`` zero-torque steps (jitted: op-by-op resets are slow on CPU)."""

    @jax.jit
    def run(key):
        state, info = jarena.batch_reset(arena, key, n)
        for _ in range(steps):
            state, info = jarena.batch_step(arena, state, jnp.zeros((n, 1)))
        return state, info

    return run(jax.random.key(0))


def test_warm_start_shifts_the_plan_and_restarts_new_episodes(arena):
    # With one sample, predictive sampling keeps its nominal plan: the act must apply plan[0] and keep
    # the plan shifted by one step (padded with its last action), per arena.
    agent = make_predictive_sampling({"samples": 1, "horizon": 4}, arena=arena)
    state = agent.init(jax.random.key(0), arena.spec, 2)
    np.testing.assert_array_equal(state.plan, np.zeros((2, 4, 1)))
    plan = jnp.arange(8.0).reshape(2, 4, 1) / 10
    state = state.replace(plan=plan)
    arena_state, info = _batch(arena, 2)
    act = jax.jit(agent.act)
    action, next_state = act(state, info, jax.random.key(1), arena.privileged(arena_state))
    np.testing.assert_allclose(action, plan[:, 0])
    np.testing.assert_allclose(next_state.plan, jax.vmap(lambda p: shift_plan(p, p[-1]))(plan))
    # a new episode (info.step == 0) in arena 1 restarts its plan from the no-op; arena 0 keeps its own
    info = info.replace(step=jnp.array([5, 0], jnp.int32))
    action, fresh = act(state, info, jax.random.key(1), arena.privileged(arena_state))
    np.testing.assert_allclose(action[0], plan[0, 0])
    np.testing.assert_allclose(action[1], [0.0])
    np.testing.assert_allclose(fresh.plan[1], np.zeros((4, 1)))
    # reset(mask) restarts only the masked arenas
    reset = agent.reset(state, jnp.array([True, False]))
    np.testing.assert_allclose(reset.plan[0], np.zeros((4, 1)))
    np.testing.assert_allclose(reset.plan[1], plan[1])


def test_mppi_act_applies_the_improved_plan_per_arena(arena):
    config = {"samples": 32, "horizon": 8, "iterations": 2, "temperature": 2.0}
    agent = make_mppi(config, arena=arena)
    arena_state, info = _batch(arena, 3, steps=2)
    state = agent.init(jax.random.key(0), arena.spec, 3)
    key = jax.random.key(7)
    action, next_state = jax.jit(agent.act)(state, info, key, arena.privileged(arena_state))
    improve = mppi_improve(arena_model(arena), MPPIConfig(**config))
    plans = jax.jit(jax.vmap(improve))(arena_state, state.plan, jax.random.split(key, 3))
    np.testing.assert_allclose(action, plans[:, 0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(next_state.plan, jax.vmap(lambda p: shift_plan(p, p[-1]))(plans), rtol=1e-5,
                               atol=1e-6)
    assert bool(jnp.all(jnp.abs(action) <= 2.0)) and float(jnp.std(action)) > 0  # distinct per arena
    again, _ = jax.jit(agent.act)(state, info, key, arena.privileged(arena_state))
    np.testing.assert_array_equal(action, again)  # same key, same action
    other, _ = jax.jit(agent.act)(state, info, jax.random.key(8), arena.privileged(arena_state))
    assert not np.allclose(action, other)


def test_planners_are_registered_and_check_their_config(arena):
    assert {"mppi", "cem", "predictive_sampling"} <= set(jarena_agents.list_agents("planner"))
    for name in ("mppi", "cem", "predictive_sampling"):
        agent = jarena_agents.build_agent(name, jarena.retrieve_config(name, arena))
        assert agent.privileged and agent.config["arena"] == PENDULUM
        with pytest.raises(ConfigError, match=f"agent '{name}' plans with the arena's own dynamics.*arena="):
            jarena_agents.build_agent(name, {"samples": 8})
    with pytest.raises(ConfigError, match="'samples' of agent 'mppi' must be >= 1"):
        make_mppi({"samples": 0}, arena=arena)
    with pytest.raises(ConfigError, match="'temperature' of agent 'mppi' must be > 0"):
        make_mppi({"temperature": 0.0}, arena=arena)
    with pytest.raises(ConfigError, match="'warm_start' of agent 'mppi' must be one of \\['last', 'no_op'\\]"):
        make_mppi({"warm_start": "zero"}, arena=arena)
    with pytest.raises(ConfigError, match="'elite_fraction' of agent 'cem' must be in \\(0, 1\\]"):
        jarena_agents.build_agent("cem", {"arena": PENDULUM, "elite_fraction": 1.5})
    with pytest.raises(ConfigError, match="cannot plan in arena 'classic\\|domain:cartpole'.*Discrete"):
        jarena_agents.build_agent("mppi", {"arena": "classic|domain:cartpole"})


def test_planner_refuses_another_arena(arena):
    agent = make_mppi({"samples": 4, "horizon": 3}, arena=arena)
    with pytest.raises(ValueError, match="model of arena 'classic\\|domain:pendulum'.*classic-point_mass-reach"):
        agent.init(jax.random.key(0), jarena.build_arena("classic|domain:point_mass").spec, 2)
    other = jarena.build_arena("classic|domain:pendulum,action:repeat(2)")
    arena_state, info = _batch(other, 2, steps=0)
    state = agent.init(jax.random.key(0), other.spec, 2)  # same spec: caught at act
    with pytest.raises(ValueError, match="does not fit model"):
        agent.act(state, info, jax.random.key(0), other.privileged(arena_state))


def test_planner_runs_under_auto_reset():
    # 20-step episodes, 40 steps: the runner resets the agent where episodes end, restarting the plan.
    arena = jarena.build_arena("classic|domain:pendulum,time_limit:20")
    agent = make_mppi({"samples": 16, "horizon": 5}, arena=arena)
    rollout = jarena.perform_parallel(agent, arena, jax.random.key(0), 2, 40)
    assert rollout.actions.shape == (40, 2, 1) and bool(jnp.all(jnp.abs(rollout.actions) <= 2.0))
    assert bool(jnp.all(rollout.infos.done[19])) and bool(jnp.all(rollout.infos.done[39]))
    np.testing.assert_array_equal(rollout.agent_state.plan, np.zeros((2, 5, 1)))  # reset after the last step
    assert float(jnp.abs(rollout.actions[20:]).max()) > 0.5  # and planning went on in the new episodes
