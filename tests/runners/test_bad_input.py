"""Runners refuse bad input before compiling: agents that do not fit the arena, bad counts and ids."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.core.agent import AgentArenaMismatch, check_agent_fits
from jarena.runners.evaluate import _compiled_episodes


def test_an_oracle_on_another_arena_family_says_what_it_is_made_for(pendulum):
    oracle = jarena_agents.build_agent("oracle_cartpole")
    assert oracle.made_for == ("cartpole",)
    compiled = _compiled_episodes.cache_info().currsize
    with pytest.raises(AgentArenaMismatch, match="agent 'oracle_cartpole' does not fit arena 'classic\\|domain:"
                                                 "pendulum': oracle_cartpole is made for arenas with 'cartpole' "
                                                 "dynamics; got classic-pendulum-swingup, whose dynamics are "
                                                 "'pendulum'"):
        jarena.evaluate(oracle, pendulum)
    assert _compiled_episodes.cache_info().currsize == compiled  # refused before compiling
    assert issubclass(AgentArenaMismatch, ValueError)  # the CLI reports it as an error line


def test_an_agent_whose_functions_fail_on_the_arena_names_the_specs_and_the_error(pendulum):
    undeclared = dataclasses.replace(jarena_agents.build_agent("oracle_cartpole"), made_for=())
    with pytest.raises(AgentArenaMismatch) as error:
        jarena.evaluate(undeclared, pendulum)
    message = str(error.value)
    assert "agent 'oracle_cartpole' does not fit arena" in message
    assert "AttributeError: 'PendulumState' object has no attribute 'x'" in message
    assert f"observation spec: {pendulum.observation_spec}" in message
    assert f"action spec: {pendulum.action_spec}" in message
    with pytest.raises(AgentArenaMismatch, match="PendulumState"):
        jarena.run(undeclared, pendulum, jax.random.key(0))
    with pytest.raises(AgentArenaMismatch, match="PendulumState"):
        jarena.perform_parallel(undeclared, pendulum, jax.random.key(0), 2, 3)


def test_an_action_that_does_not_fit_the_action_spec_is_a_mismatch(cartpole):
    continuous = jarena_agents.build_agent("oracle_pendulum")  # float (1,) torques for a Discrete(2) arena
    with pytest.raises(AgentArenaMismatch, match="made for arenas with 'pendulum' dynamics"):
        jarena.perform_parallel(continuous, cartpole, jax.random.key(0), 2, 3)
    with pytest.raises(AgentArenaMismatch, match="AttributeError: 'Discrete' object has no attribute 'low'"):
        check_agent_fits(dataclasses.replace(continuous, made_for=()), cartpole)  # it clips to the spec's bounds
    floats = jarena.Agent(name="floats", init=lambda key, spec, num_arenas: (),
                          act=lambda state, info, key, privileged: (jnp.zeros(info.reward.shape + (3,)), state))
    with pytest.raises(AgentArenaMismatch, match=r"agent 'floats' does not fit.*SpecError: action: expected a "
                                                 r"scalar integer in \[0, 2\)"):
        jarena.evaluate(floats, cartpole)


def test_the_check_passes_fitting_agents_and_is_cached(cartpole):
    agent = jarena_agents.build_agent("oracle_cartpole")
    renamed = dataclasses.replace(cartpole, name="my-cartpole")  # the family is the dynamics, not the name
    check_agent_fits(agent, renamed)
    check_agent_fits(agent, cartpole)
    hits = check_agent_fits.cache_info().hits
    jarena.perform_parallel(agent, cartpole, jax.random.key(0), 2, 3)
    assert check_agent_fits.cache_info().hits == hits + 1  # no second trace


@pytest.mark.parametrize("kwargs, message", [
    (dict(num_arenas=0, num_steps=3), "num_arenas must be an integer >= 1, got 0"),
    (dict(num_arenas=-2, num_steps=3), "num_arenas must be an integer >= 1, got -2"),
    (dict(num_arenas=2, num_steps=-1), "num_steps must be an integer >= 1, got -1"),
    (dict(num_arenas=2, num_steps=0), "num_steps must be an integer >= 1, got 0"),
    (dict(num_arenas=2.5, num_steps=3), "num_arenas must be an integer >= 1, got 2.5"),
])
def test_perform_parallel_refuses_empty_or_negative_counts(cartpole, kwargs, message):
    with pytest.raises(ValueError, match=f"perform_parallel: {message}"):
        jarena.perform_parallel(jarena_agents.build_agent("random"), cartpole, jax.random.key(0), **kwargs)


@pytest.mark.parametrize("kwargs, message", [
    (dict(max_steps=-1), "run: max_steps must be an integer >= 1, got -1"),
    (dict(max_steps=0), "run: max_steps must be an integer >= 1, got 0"),
    (dict(episode=-5), r"run: episode: invalid episode id\(s\) \[-5\]; valid ids are in \[0, 2\^31\)"),
])
def test_run_refuses_bad_max_steps_and_episode_ids(cartpole, kwargs, message):
    with pytest.raises(ValueError, match=message):
        jarena.run(jarena_agents.build_agent("random"), cartpole, jax.random.key(0), **kwargs)


def test_tasks_without_success_report_it_as_not_applicable():
    """The suite's walker defines no success: its results say "n/a" and keep it out of the summary, while
    cartpole's success rate stays a number."""
    import jax

    import jarena
    import jarena_agents

    assert not jarena.build_arena("dmc|domain:walker,task:walk").task.has_success
    assert jarena.build_arena("dmc|domain:cartpole,task:balance").task.has_success
    pendulum = jarena.build_arena("classic|domain:pendulum")
    blind = jarena.Arena(dynamics=pendulum.dynamics, sensor=pendulum.sensor,
                         task=jarena.chain(jarena.Task(update=lambda s, o, t, p: (o, s)), jarena.tasks.time_limit(5)))
    random = jarena_agents.build_agent("random")
    result = jarena.evaluate(random, blind, jax.random.key(0), episodes=[0, 1])
    assert "success_rate" not in result.summary() and result.per_episode()[0]["success"] is None
    assert "| success rate     | n/a (the task defines none)" in result.table()
    counted = jarena.evaluate(random, pendulum, jax.random.key(0), episodes=[0, 1])
    assert counted.summary()["success_rate"] == 0.0 and "success rate     | 0.0%" in counted.table()


def test_evaluate_refuses_negative_episode_ids_and_step_caps(cartpole):
    import jax

    import jarena
    import jarena_agents

    oracle = jarena_agents.build_agent("oracle_cartpole")
    with pytest.raises(ValueError, match=r"evaluate.*-5"):
        jarena.evaluate(oracle, cartpole, jax.random.key(0), episodes=[0, -5])
    with pytest.raises(ValueError, match=r"evaluate: invalid episode id\(s\) \[4294967301\]"):  # not wrapped to 5
        jarena.evaluate(oracle, cartpole, jax.random.key(0), episodes=np.asarray([0, 2**32 + 5]))
    for bad in (0, -1):
        with pytest.raises(ValueError, match="evaluate: max_steps must be an integer >= 1"):
            jarena.evaluate(oracle, cartpole, jax.random.key(0), episodes=[0], max_steps=bad)
