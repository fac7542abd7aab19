"""jarena arenas exported as dm_env environments: dm_env's own conformance tests pass, the specs of the suite's
arenas are dm_control's, and episodes end with dm_env's discounts."""

import dm_env
import jax
import numpy as np
import pytest
from absl.testing import absltest
from dm_env import test_utils

import jarena
from jarena.interop.dm_env import SPECS, array_spec, to_dm_env

CARTPOLE = "classic|domain:cartpole"


class ClassicCartpoleConforms(test_utils.EnvironmentTestMixin, absltest.TestCase):
    """dm_env's conformance suite (reset, step after reset, a fresh env's first step, a long run) on classic
    cartpole, with random actions that end several episodes."""

    def make_object_under_test(self):
        return to_dm_env(jarena.build_arena(CARTPOLE), seed=0)

    def make_action_sequence(self):
        yield from np.random.default_rng(0).integers(0, 2, 300).astype(np.int32)


class SuiteCartpoleConforms(test_utils.EnvironmentTestMixin, absltest.TestCase):
    def make_object_under_test(self):
        return to_dm_env(jarena.build_arena("dmc|domain:cartpole,task:balance"), seed=0)


@pytest.fixture(scope="module")
def cartpole():
    return jarena.build_arena(CARTPOLE)


def test_the_suites_specs_are_dm_controls():
    from dm_control import suite

    reference = suite.load("cartpole", "balance")
    env = to_dm_env(jarena.build_arena("dmc|domain:cartpole,task:balance"))
    ours, theirs = env.observation_spec(), reference.observation_spec()
    assert set(ours) == set(theirs)
    for key in theirs:
        assert ours[key].shape == theirs[key].shape and ours[key].dtype == np.float32, key
    action, reference_action = env.action_spec(), reference.action_spec()
    assert action.shape == reference_action.shape
    np.testing.assert_array_equal(action.minimum, reference_action.minimum)
    np.testing.assert_array_equal(action.maximum, reference_action.maximum)
    assert env.reward_spec() == reference.reward_spec() and env.discount_spec() == reference.discount_spec()


def test_termination_has_discount_zero_and_the_next_step_restarts(cartpole):
    env = to_dm_env(cartpole, seed=1)
    step = env.reset()
    assert step.first() and step.reward is None
    while not step.last():
        step = env.step(np.int32(0))  # always push left: the pole falls
    assert step.discount == 0.0 and step.reward == 1.0
    assert env.step(np.int32(0)).first()  # dm_env: the step after the last starts an episode


def test_the_time_limit_truncates_with_discount_one():
    env = to_dm_env(jarena.build_arena("classic|domain:cartpole,time_limit:4"), seed=0)
    steps = [env.reset()] + [env.step(np.int32(t % 2)) for t in range(4)]  # alternate: the pole stays up
    assert [s.step_type for s in steps] == [dm_env.StepType.FIRST] + [dm_env.StepType.MID] * 3 + [dm_env.StepType.LAST]
    assert steps[-1].discount == 1.0


def test_fixed_episodes_are_the_arenas(cartpole):
    episodes = list(cartpole.episodes("eval"))[:2]
    env = to_dm_env(cartpole, episodes=episodes)
    for episode in episodes + episodes[:1]:  # in order, cycling
        _, info = cartpole.reset(None, episode=episode)
        np.testing.assert_array_equal(env.reset().observation["state"], jax.device_get(info.observation["state"]))


def test_seeded_envs_repeat():
    def run(seed):
        env = to_dm_env(jarena.build_arena(CARTPOLE), seed=seed)
        return np.stack([env.reset().observation["state"] for _ in range(3)])

    np.testing.assert_array_equal(run(3), run(3))
    assert not np.array_equal(run(3), run(4))


def test_bad_arguments_are_named(cartpole):
    with pytest.raises(ValueError, match="at least one episode id"):
        to_dm_env(cartpole, episodes=[])
    with pytest.raises(TypeError, match="convertible: " + ", ".join(t.__name__ for t in SPECS)):
        array_spec(object())
