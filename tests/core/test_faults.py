"""Faults under jit and in batches: invalid actions and non-finite states end the episode with a typed flag."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.core import faults
from jarena.core.faults import INVALID_ACTION, NONFINITE_STATE
from jarena.core.spec import Box, Dict, Discrete, Tuple
from jarena.testing.contract import check_rollout

PENDULUM = "classic|domain:pendulum,task:swingup"


def finite(tree) -> bool:
    return all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree_util.tree_leaves(tree)
               if jnp.issubdtype(x.dtype, jnp.inexact))


def blowing_up(arena: jarena.Arena) -> jarena.Arena:
    """Pendulum whose default params overflow the state in one step (dt = 1e30, no speed limit)."""
    params = arena.dynamics.default_params().replace(dt=jnp.float32(1e30), max_speed=jnp.float32(jnp.inf))
    return dataclasses.replace(arena, dynamics=dataclasses.replace(arena.dynamics, default_params=lambda: params))


@pytest.fixture(scope="module")
def pendulum():
    return jarena.build_arena(PENDULUM)


def test_describe_names_and_counts_fault_bits():
    assert faults.describe(0) == [] and faults.describe(np.int32(INVALID_ACTION)) == ["invalid action"]
    assert faults.describe(INVALID_ACTION | NONFINITE_STATE) == ["invalid action", "non-finite state"]
    assert faults.describe(8) == ["bit 3"]
    assert faults.describe_counts(np.array([0, 1, 2, 3, 1])) == {"invalid action": 3, "non-finite state": 2}
    assert faults.describe_counts(np.zeros(4, np.int32)) == {}
    assert all(f.description for f in faults.Fault)


def test_valid_action_faults_only_what_dynamics_cannot_clip():
    valid = jax.jit(faults.valid_action, static_argnums=0)
    box = Box(-1.0, 1.0, (2,))
    assert bool(valid(box, jnp.array([5.0, -7.0])))  # out of bounds: dynamics clip, no fault
    assert not bool(valid(box, jnp.array([0.0, jnp.nan]))) and not bool(valid(box, jnp.array([jnp.inf, 0.0])))
    assert bool(valid(Discrete(3), jnp.int32(2)))
    assert not bool(valid(Discrete(3), jnp.int32(3))) and not bool(valid(Discrete(3), jnp.int32(-1)))
    assert not bool(valid(Box(0, 4, (2,), jnp.int32), jnp.array([1, 5], jnp.int32)))
    nested = Dict(move=Box(-1.0, 1.0, (1,)), pick=Tuple([Discrete(2), Box(0, 1, (), bool)]))
    good = {"move": jnp.array([3.0]), "pick": (jnp.int32(1), jnp.array(True))}
    assert bool(valid(nested, good))
    assert not bool(valid(nested, {**good, "pick": (jnp.int32(2), jnp.array(True))}))
    assert not bool(valid(nested, {**good, "move": jnp.array([jnp.nan])}))


def test_nan_action_under_jit_is_an_invalid_action_that_ends_the_episode(pendulum):
    params = pendulum.default_params()
    state, info = pendulum.reset(jax.random.key(0), params)
    assert int(info.fault) == 0 and not bool(info.faulted)
    step = jax.jit(pendulum.step)
    no_op_state, _ = step(state, pendulum.no_op(), params)
    for bad in (jnp.nan, jnp.inf, -jnp.inf):
        next_state, info = step(state, jnp.array([bad], jnp.float32), params)
        assert int(info.fault) == INVALID_ACTION and bool(info.faulted)
        assert bool(info.terminated) and float(info.reward) == 0.0 and not bool(info.success)
        assert finite(info.observation) and finite(info.final.observation)
        # the no-op ran in place of the invalid action: the state stays finite
        np.testing.assert_array_equal(next_state.physics.theta, no_op_state.physics.theta)
    # a torque beyond the bounds is clipped by the dynamics, as Gymnasium's: no fault
    _, info = step(state, jnp.array([5.0], jnp.float32), params)
    assert int(info.fault) == 0 and not bool(info.terminated) and float(info.reward) < 0


def test_physics_blow_up_is_a_nonfinite_state_fault(pendulum):
    params = pendulum.default_params()
    params = params.replace(dynamics=params.dynamics.replace(dt=jnp.float32(1e30), max_speed=jnp.float32(jnp.inf)))
    state, info = jax.jit(pendulum.reset)(jax.random.key(0), params)
    next_state, info = jax.jit(pendulum.step)(state, jnp.array([1.0], jnp.float32), params)
    assert not finite(next_state.physics)  # the premise: the state overflowed
    assert int(info.fault) == NONFINITE_STATE
    assert bool(info.terminated) and float(info.reward) == 0.0
    assert finite(info.observation) and finite(info.final.observation)
    assert not pendulum.dynamics.is_finite(next_state.physics) and pendulum.dynamics.is_finite(state.physics)


def test_a_blow_up_leaves_no_nan_in_reward_terms_metrics_or_any_reported_mean(pendulum):
    """Pendulum's metric ``upright`` is cos(theta), NaN once theta overflows: a faulted step reports 0 there,
    so the evaluation's summary (metric means included) is finite and counts every episode as faulted."""
    import jarena_agents

    params = pendulum.default_params()
    params = params.replace(dynamics=params.dynamics.replace(dt=jnp.float32(1e30), max_speed=jnp.float32(jnp.inf)))
    state, _ = jax.jit(pendulum.reset)(jax.random.key(0), params)
    _, info = jax.jit(pendulum.step)(state, jnp.array([1.0], jnp.float32), params)
    assert info.metrics and finite(info.metrics) and finite(info.reward_terms)
    result = jarena.evaluate(jarena_agents.build_agent("random"), pendulum, jax.random.key(0), params=params,
                             episodes=[0, 1, 2])
    assert result.num_faulted == 3 and all(np.isfinite(v) for v in result.summary().values())


@pytest.mark.parametrize("bad", [7, -1, 2])
def test_out_of_range_discrete_action_under_jit_runs_the_no_op(bad):
    arena = jarena.build_arena("classic|domain:cartpole,task:balance")
    state, _ = arena.reset(jax.random.key(0))
    step = jax.jit(arena.step)
    next_state, info = step(state, jnp.int32(bad))
    assert int(info.fault) == INVALID_ACTION and bool(info.terminated)
    assert finite(next_state.physics) and finite(info.observation)
    expected, _ = step(state, arena.no_op())
    for a, b in zip(jax.tree_util.tree_leaves(next_state.physics), jax.tree_util.tree_leaves(expected.physics),
                    strict=True):
        np.testing.assert_array_equal(a, b)
    for good in (0, 1):
        assert int(step(state, jnp.int32(good))[1].fault) == 0


@pytest.mark.parametrize("strategy", ["select", "lazy", "repeat"])
def test_batch_step_auto_resets_only_the_faulted_arena(strategy):
    arena = jarena.build_arena(f"{PENDULUM},auto_reset:{strategy}")
    states, infos = jarena.batch_reset(arena, jax.random.key(0), 4)
    actions = jnp.array([[0.5], [jnp.nan], [0.5], [0.5]], jnp.float32)
    stepped, infos = jax.jit(lambda s, a: jarena.batch_step(arena, s, a))(states, actions)
    plain_states, plain = jax.jit(lambda s, a: jarena.batch_step(arena, s, a, reset_done=False))(states, actions)
    np.testing.assert_array_equal(infos.fault, [0, INVALID_ACTION, 0, 0])
    np.testing.assert_array_equal(infos.terminated, [False, True, False, False])
    np.testing.assert_array_equal(infos.reward[1], 0.0)
    assert finite(infos.final.observation) and finite(infos.observation)
    # the faulted arena starts a new episode (the first one again under "repeat"), keeping the fault code
    np.testing.assert_array_equal(infos.step, [1, 0, 1, 1])
    np.testing.assert_array_equal(infos.final.step, [1, 1, 1, 1])
    start = jax.tree_util.tree_map(lambda x: x[1], states.physics)
    restarted = jax.tree_util.tree_map(lambda x: x[1], stepped.physics)
    if strategy == "repeat":
        assert all(np.array_equal(a, b) for a, b in zip(jax.tree_util.tree_leaves(start),
                                                        jax.tree_util.tree_leaves(restarted), strict=True))
    else:
        assert int(infos.episode[1]) != int(states.episode[1])
    # the others are untouched: the same as a step without auto-reset
    others = np.array([0, 2, 3])
    np.testing.assert_array_equal(infos.observation["state"][others], plain.observation["state"][others])
    np.testing.assert_array_equal(infos.episode[others], states.episode[others])
    np.testing.assert_array_equal(stepped.physics.theta[others], plain_states.physics.theta[others])


def test_mjx_arena_flags_a_nan_action_and_a_blow_up():
    arena = jarena.build_arena("dmc|domain:cartpole,task:balance")
    params = arena.default_params()
    state, info = jax.jit(arena.reset)(jax.random.key(0), params)
    step = jax.jit(arena.step)
    action = jnp.full(arena.action_spec.shape, jnp.nan, jnp.float32)
    _, info = step(state, action, params)
    assert int(info.fault) == INVALID_ACTION and bool(info.terminated) and float(info.reward) == 0.0
    assert finite(info.observation)
    _, info = step(state, jnp.zeros(arena.action_spec.shape, jnp.float32), params)
    assert int(info.fault) == 0 and not bool(info.terminated)
    # the MJX hook reads qpos, qvel and act only; a NaN elsewhere in mjx.Data is not its business
    assert bool(arena.dynamics.is_finite(state.physics.replace(xpos=state.physics.xpos * jnp.nan)))
    assert not bool(arena.dynamics.is_finite(state.physics.replace(qvel=state.physics.qvel.at[0].set(jnp.inf))))
    # a NaN in the physics reaches qpos/qvel within a step: NONFINITE_STATE
    _, info = step(state.replace(physics=state.physics.replace(qfrc_applied=state.physics.qfrc_applied + jnp.nan)),
                   jnp.zeros(arena.action_spec.shape, jnp.float32), params)
    assert int(info.fault) == NONFINITE_STATE and bool(info.terminated) and finite(info.observation)


def test_evaluate_reports_the_faulted_episodes_and_a_finite_return(pendulum):
    def act(state, info, key, privileged=None):
        # odd episodes give NaN from their fourth step on
        bad = (info.episode % 2 == 1) & (info.step >= 3)
        return jnp.where(bad, jnp.nan, 0.0)[:, None].astype(jnp.float32), state

    agent = jarena.Agent(name="nan_on_odd_episodes", init=lambda key, spec, n: (), act=act)
    result = jarena.evaluate(agent, pendulum, jax.random.key(0), episodes=np.arange(6))
    odd = np.arange(6) % 2 == 1
    np.testing.assert_array_equal(result.faults, np.where(odd, int(INVALID_ACTION), 0))
    np.testing.assert_array_equal(result.lengths, np.where(odd, 4, 200))
    assert np.all(np.isfinite(result.returns)) and np.isfinite(result.summary()["return_mean"])


def test_ppo_counts_faulted_episodes(pendulum):
    agent = jarena_agents.build_agent("ppo", {"num_arenas": 4, "rollout_length": 8, "minibatches": 2, "epochs": 1})
    train = jax.jit(lambda k, a: agent.train(agent.init_training(k, a), a, 1), static_argnums=1)
    _, metrics = train(jax.random.key(0), blowing_up(pendulum))  # every step overflows: every episode faults
    assert int(metrics["faulted_episodes"][0]) == int(metrics["episodes"][0]) == 4 * 8
    assert finite(metrics)
    _, metrics = train(jax.random.key(0), pendulum)
    assert int(metrics["faulted_episodes"][0]) == 0


def test_contract_rollout_catches_a_blow_up(pendulum):
    check_rollout(pendulum, jax.random.key(0), steps=20)
    with pytest.raises(AssertionError, match="faulted: \\['non-finite state'\\]"):
        check_rollout(blowing_up(pendulum), jax.random.key(0), steps=20)


def test_brax_arena_flags_a_nan_action_and_a_nan_pipeline_state():
    arena = jarena.build_arena("brax|env:inverted_pendulum")
    params = arena.default_params()
    state, _ = jax.jit(arena.reset)(jax.random.key(0), params)
    step = jax.jit(arena.step)
    zero = jnp.zeros(arena.action_spec.shape, jnp.float32)
    assert int(step(state, zero, params)[1].fault) == 0
    assert int(step(state, zero + jnp.nan, params)[1].fault) == INVALID_ACTION
    pipeline = state.physics.pipeline_state
    bad = state.replace(physics=state.physics.replace(pipeline_state=pipeline.replace(qd=pipeline.qd * jnp.nan)))
    assert not bool(arena.dynamics.is_finite(bad.physics))
    _, info = step(bad, zero, params)
    assert int(info.fault) == NONFINITE_STATE and bool(info.terminated) and finite(info.observation)
