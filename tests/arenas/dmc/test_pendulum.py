import jax
import numpy as np

import jarena
from jarena.core.types import Outcome, Transition
from tests.arenas.dmc.reference import check_episode_length_and_timestep, compare, compare_states, reset_batch


def _near_upright(rng, physics):
    """Half the states within ~11 degrees of upright, where the 8-degree reward switches."""
    if rng.rand() < 0.5:
        physics.named.data.qpos["hinge"] = rng.uniform(-0.2, 0.2)


def test_observation_and_reward_match_dm_control():
    result = compare("pendulum", "swingup", states_per_seed=8, adjust=_near_upright)
    rewards = np.asarray(result["rewards"])
    assert (rewards == 1).any() and (rewards == 0).any()  # both sides of the sparse reward compared


def test_initial_states_follow_the_suite():
    arena, states, infos = reset_batch("pendulum", "swingup")
    qpos = np.asarray(states.physics.qpos[:, 0])
    assert qpos.min() >= -np.pi and qpos.max() < np.pi
    assert 1.5 < qpos.std() < 2.1  # uniform on [-pi, pi): std pi / sqrt(3) = 1.81
    assert not np.asarray(states.physics.qvel).any()
    compare_states("pendulum", "swingup", states.physics, infos.observation)  # observed as dm_control does
    np.testing.assert_array_equal(infos.success, np.cos(qpos) >= np.cos(np.deg2rad(8)))


def test_episode_length_and_timestep_match_dm_control():
    check_episode_length_and_timestep("pendulum", "swingup")


def test_mjx_step_matches_mujoco():
    """Our control step (Euler, consistent kinematics after the step) equals dm_control's, and so do the
    observation and reward on the state reached."""
    from tests.arenas.dmc.reference import dm_env, to_mjx
    arena = jarena.build_arena("dmc|domain:pendulum,task:swingup")
    params = arena.default_params()
    env = dm_env("pendulum", "swingup", 0)
    env.reset()
    data = to_mjx(arena.dynamics.render.model, env.physics)

    @jax.jit
    def step(d, u):
        d = arena.dynamics.step(d, u, params.dynamics)
        outcome, _ = arena.task.update(((), 0), Outcome.empty(), Transition(d, u, d, params.dynamics), params.task)
        return d, arena.sensor.observe(d, params.sensor), outcome.reward

    rng = np.random.RandomState(0)
    for _ in range(20):
        u = rng.uniform(-1, 1, (1,)).astype(np.float32)
        timestep = env.step(u)
        data, obs, reward = step(data, u)
        for k, v in timestep.observation.items():
            np.testing.assert_allclose(obs[k], v, atol=1e-4)
        assert float(reward) == timestep.reward
    np.testing.assert_allclose(data.qpos, env.physics.data.qpos, atol=1e-4)
    np.testing.assert_allclose(data.qvel, env.physics.data.qvel, atol=1e-3)
