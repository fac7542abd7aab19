"""jarena arenas exported to Gymnasium: Gymnasium's env checker passes, the env steps exactly as the arena does,
the vector env follows Gymnasium's same-step autoreset with the final observation in ``info``, actions outside
the space raise as in Gymnasium's own environments, and a step after the episode ended needs a reset."""

import gymnasium
import jax
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import jarena
from jarena.interop.gymnasium import SPACES, InvalidAction, _check_action, space, to_gymnasium, to_gymnasium_vector

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


def test_an_action_outside_the_space_raises_as_in_gymnasiums_cartpole(cartpole):
    assert all(issubclass(InvalidAction, t) for t in (gymnasium.error.InvalidAction, AssertionError, ValueError))
    env, theirs = to_gymnasium(cartpole), gymnasium.make("CartPole-v1")
    env.reset(seed=0)
    theirs.reset(seed=0)
    for action in [2, -1, 5, 0.5, 1.0, np.float32(0), np.array([0, 1]), np.array([1]), "1", None]:
        with pytest.raises(AssertionError):  # CartPole-v1 asserts action_space.contains(action)
            theirs.step(action)
        with pytest.raises(AssertionError) as raised:
            env.step(action)
        message = str(raised.value)
        assert isinstance(raised.value, InvalidAction)
        assert repr(action) in message and "Discrete(2)" in message and "integers 0 to 1" in message
    for t, action in enumerate([0, 1, np.int64(1), np.array(0), np.uint8(1)], 1):  # valid in both
        theirs.step(action)
        assert env.step(action)[4]["step"] == t  # the invalid actions did not step the arena


def test_the_vector_env_raises_on_one_bad_action_among_valid_ones(cartpole):
    envs = to_gymnasium_vector(cartpole, 4)
    envs.reset(seed=0)
    with pytest.raises(InvalidAction, match=r"envs \[2\] are not in the single action space Discrete\(2\)"):
        envs.step(np.array([0, 1, 2, 0]))
    with pytest.raises(ValueError, match=r"are not 4 actions .* got int64 of shape \(3,\)"):
        envs.step(np.array([0, 1, 0]))
    with pytest.raises(AssertionError, match="of an integer dtype; got float64"):
        envs.step(np.array([0.0, 1.0, 1.0, 0.0]))
    assert (envs.step(np.array([0, 1, 1, 0]))[4]["step"] == 1).all()
    pendulums = to_gymnasium_vector(jarena.build_arena("classic|domain:pendulum,task:swingup"), 3)
    pendulums.reset(seed=0)
    with pytest.raises(InvalidAction, match=r"envs \[1\] .* must be finite"):
        pendulums.step(np.array([[0.0], [np.nan], [50.0]], np.float32))


def test_box_actions_out_of_bounds_are_clipped_as_by_pendulum_but_not_finite_ones_raise():
    env = to_gymnasium(jarena.build_arena("classic|domain:pendulum,task:swingup"))
    theirs = gymnasium.make("Pendulum-v1")

    def first_observation(env, torque):
        env.reset(seed=3)
        return env.step(np.array([torque], np.float32))[0]

    for outside, bound in [(100.0, 2.0), (-7.5, -2.0)]:  # neither raises: both clip to the bound
        np.testing.assert_array_equal(first_observation(env, outside), first_observation(env, bound))
        np.testing.assert_array_equal(first_observation(theirs, outside), first_observation(theirs, bound))
    env.reset(seed=0)
    box = r"is not in the action space Box\(-2.0, 2.0, \(1,\), float32\)"
    for action in [np.array([np.nan], np.float32), np.array([np.inf]), np.array([-np.inf])]:
        with pytest.raises(InvalidAction, match=box + ": values must be finite"):
            env.step(action)
    for action in [np.array([1.0, 2.0]), 1.0, np.array([True])]:
        with pytest.raises(InvalidAction, match=r"expected an array of shape \(1,\) of a float or integer dtype"):
            env.step(action)
    assert env.step(np.array([1]))[4]["step"] == 1  # integers are valid for a float Box


def test_dict_and_tuple_actions_are_checked_per_entry():
    action_space = gymnasium.spaces.Dict({"grip": gymnasium.spaces.Discrete(3),
                                          "move": gymnasium.spaces.Tuple((gymnasium.spaces.Box(-1, 1, (2,)),))})
    _check_action(action_space, {"grip": 2, "move": (np.array([5.0, -1.0]),)})
    for action, match in [({"grip": 3, "move": (np.zeros(2),)}, r"action\['grip'\] 3 .* integers 0 to 2"),
                          ({"grip": 0, "move": (np.array([0.0, np.nan]),)}, r"action\['move'\]\[0\] .* finite"),
                          ({"grip": 0}, r"expected a dict with keys \['grip', 'move'\]"),
                          ({"grip": 0, "move": np.zeros(2)}, r"action\['move'\] .* expected a tuple of 1")]:
        with pytest.raises(InvalidAction, match=match):
            _check_action(action_space, action)
    with pytest.raises(InvalidAction, match=r"actions\['grip'\] .* envs \[1\] are not in"):
        _check_action(action_space, {"grip": np.array([0, 3]), "move": (np.zeros((2, 2)),)}, (2,), "actions")


def test_a_step_after_the_episode_ended_needs_a_reset(cartpole):
    env = to_gymnasium(jarena.build_arena("classic|domain:cartpole,time_limit:4"))
    env.reset(seed=0)
    ended = [env.step(0)[2:4] for _ in range(4)]
    assert ended == [(False, False)] * 3 + [(False, True)]
    with pytest.raises(gymnasium.error.ResetNeeded, match=r"the episode ended \(truncated\); call reset\(\)"):
        env.step(0)
    env.reset(seed=0)
    assert env.step(0)[4]["step"] == 1
    env = to_gymnasium(cartpole)
    env.reset(seed=0)
    for _ in range(30):  # pushing one way drops the pole
        _, _, terminated, truncated, _ = env.step(1)
        if terminated:
            break
    assert terminated and not truncated
    with pytest.raises(gymnasium.error.ResetNeeded, match=r"the episode ended \(terminated\); call reset\(\)"):
        env.step(1)
    env.reset(seed=0)
    assert env.step(1)[4]["step"] == 1
