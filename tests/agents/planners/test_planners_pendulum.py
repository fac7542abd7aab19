"""Quality bar: the planners with their shipped configs swing up and balance classic pendulum."""

import jax
import pytest

import jarena
import jarena_agents

PENDULUM = "classic|domain:pendulum"
EPISODES = list(range(8))  # the first 8 eval episodes: 3 start hanging nearly straight down


@pytest.fixture(scope="module")
def arena():
    return jarena.build_arena(PENDULUM)


@pytest.fixture(scope="module")
def random_return(arena):
    result = jarena.evaluate(jarena_agents.build_agent("random"), arena, jax.random.key(0), episodes=EPISODES)
    return result.summary()["return_mean"]


def _evaluate(name, arena):
    agent = jarena_agents.build_agent(name, jarena.retrieve_config(name, arena))  # the shipped config
    return jarena.evaluate(agent, arena, jax.random.key(0), episodes=EPISODES).summary()


def test_mppi_swings_up_pendulum(arena, random_return):
    summary = _evaluate("mppi", arena)
    assert summary["return_mean"] > -200
    assert summary["success_rate"] == 1.0
    assert random_return < -900


@pytest.mark.parametrize("name", ["cem", "predictive_sampling"])
def test_cem_and_predictive_sampling_beat_random_on_pendulum(arena, random_return, name):
    summary = _evaluate(name, arena)
    assert summary["return_mean"] > random_return + 600
    assert summary["return_mean"] > -250
    assert summary["success_rate"] >= 0.75
