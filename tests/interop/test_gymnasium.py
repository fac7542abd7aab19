"""jarena arenas exported to Gymnasium: Gymnasium's env checker passes, the env steps exactly as the arena does,
and the vector env follows Gymnasium's same-step autoreset with the final observation in ``info``."""

import gymnasium
import jax
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import jarena
from jarena.interop.gymnasium import SPACES, space, to_gymnasium, to_gymnasium_vector

CARTPOLE = "classic|domain:cartpole"


@pytest.fixture(scope="module")
def cartpole():
    return jarena.build_arena(CARTPOLE)


def test_classic_env_passes_gymnasiums_checker_and_renders(cartpole):
    env = to_gymnasium(cartpole, render_mode="rgb_array", render_size=(64, 48))
    check_env(env, skip_render_check=False)
    assert env.observation_space == gymnasium.spaces.Box(env.observation_space.low, env.observation_space.high,
                                                         (4,), np.float32)
    assert env.action_space == gymnasium.spaces.Discrete(2)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8 and frame.std() > 0


def test_mjx_env_passes_gymnasiums_checker():
    env = to_gymnasium(jarena.build_arena("dmc|domain:cartpole,task:balance"), flatten=False)
    check_env(env, skip_render_check=True)
    assert isinstance(env.observation_space, gymnasium.spaces.Dict)
    assert set(env.observation_space.spaces) == {"position", "velocity"}
    assert env.action_space.shape == (1,) and env.action_space.dtype == np.float32


def test_env_steps_exactly_as_the_arena(cartpole):
    env = to_gymnasium(cartpole)
    observation, info = env.reset(seed=7)
    # compiled with params as an input, as the env's (eager arithmetic, or params folded into the program as
    # constants, may round differently in the last bit)
    reset, step, params = jax.jit(cartpole.reset), jax.jit(cartpole.step), cartpole.default_params()
    state, arena_info = reset(jax.random.key(7), params)
    np.testing.assert_array_equal(observation, arena_info.observation["state"])
    assert info["episode_id"] == int(arena_info.episode) and info["step"] == 0
    actions = np.random.default_rng(0).integers(0, 2, 500)
    for t, action in enumerate(actions):
        observation, reward, terminated, truncated, info = env.step(int(action))
        state, arena_info = step(state, np.int32(action), params)
        np.testing.assert_array_equal(observation, arena_info.observation["state"])
        assert reward == float(arena_info.reward) and terminated == bool(arena_info.terminated)
        assert truncated == bool(arena_info.truncated) and info["step"] == t + 1
        if terminated or truncated:
            break
    assert terminated or truncated  # random actions drop the pole well within 500 steps


def test_a_fixed_episode_is_the_arenas_eval_episode(cartpole):
    env = to_gymnasium(cartpole)
    episode = list(cartpole.episodes("eval"))[3]
    observation, info = env.reset(options={"episode": episode})
    _, arena_info = cartpole.reset(None, episode=episode)
    np.testing.assert_array_equal(observation, arena_info.observation["state"])
    assert info["episode_id"] == episode


def test_vector_env_resets_in_the_same_step_with_the_final_observation_in_info(cartpole):
    envs = to_gymnasium_vector(cartpole, 4)
    assert envs.metadata["autoreset_mode"] == gymnasium.vector.AutoresetMode.SAME_STEP
    episodes = list(cartpole.episodes("eval"))[:4]
    observations, infos = envs.reset(options={"episode": episodes})
    assert observations.shape == (4, 4) and envs.observation_space.contains(observations)
    singles = [to_gymnasium(cartpole) for _ in range(4)]
    for env, episode, observation in zip(singles, episodes, observations, strict=True):
        np.testing.assert_array_equal(env.reset(options={"episode": episode})[0], observation)
    rng, ended = np.random.default_rng(1), 0
    for _ in range(200):
        actions = rng.integers(0, 2, 4)
        observations, rewards, terminated, truncated, infos = envs.step(actions)
        assert rewards.shape == (4,) and envs.observation_space.contains(observations)
        done = terminated | truncated
        for i, env in enumerate(singles):
            if env is None:
                continue
            observation, reward, term, trunc, _ = env.step(int(actions[i]))
            assert reward == rewards[i] and term == terminated[i] and trunc == truncated[i]
            if done[i]:  # the finished episode's last observation is in info; the new one is returned
                assert infos["_final_obs"][i]
                np.testing.assert_array_equal(infos["final_obs"][i], observation)
                assert infos["final_info"][i]["episode_id"] == episodes[i]
                assert infos["step"][i] == 0 and infos["episode_id"][i] != episodes[i]
                singles[i], ended = None, ended + 1
            else:
                np.testing.assert_array_equal(observations[i], observation)
        if ended == 4:
            break
    assert ended == 4


def test_vector_env_is_repeatable_from_a_seed(cartpole):
    def run(seed):
        envs = to_gymnasium_vector(cartpole, 3)
        observations = [envs.reset(seed=seed)[0]]
        for t in range(30):
            observations.append(envs.step(np.full(3, t % 2))[0])
        return np.stack(observations)

    np.testing.assert_array_equal(run(5), run(5))
    assert not np.array_equal(run(5), run(6))


def test_gymnasiums_vector_wrappers_run_on_it(cartpole):
    envs = gymnasium.wrappers.vector.RecordEpisodeStatistics(to_gymnasium_vector(cartpole, 8))
    envs.reset(seed=0)
    returns = []
    for _ in range(300):
        _, _, _, _, infos = envs.step(envs.action_space.sample())
        if "episode" in infos:
            returns += list(infos["episode"]["r"][infos["_episode"]])
    assert len(returns) >= 8 and all(r >= 8 for r in returns)  # cartpole pays 1 per step, episodes last >= 8


def test_bad_arguments_are_named(cartpole):
    with pytest.raises(ValueError, match="render_mode must be None or 'rgb_array'"):
        to_gymnasium(cartpole, render_mode="human")
    with pytest.raises(ValueError, match="num_envs must be a positive integer"):
        to_gymnasium_vector(cartpole, 0)
    with pytest.raises(TypeError, match="convertible: " + ", ".join(t.__name__ for t in SPACES)):
        space(object())
    env = to_gymnasium(cartpole)
    with pytest.raises(gymnasium.error.ResetNeeded):
        env.step(0)
