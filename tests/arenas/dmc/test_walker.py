import jax
import numpy as np
import pytest

import jarena
from jarena.arenas.dmc import walker
from tests.arenas.dmc.reference import assert_suite_episodes, compare, compare_resets, dm_env, perturb, resets, to_mjx

TASKS = ["stand", "walk", "run"]


def standing(rng, physics):
    """Upright around the standing height, moving forward at up to 10 m/s: every reward term varies."""
    perturb(rng, physics, 0.05)
    q, v = physics.named.data.qpos, physics.named.data.qvel
    q["rootz"] = rng.uniform(-0.6, 0.2)  # torso at 0.7 to 1.5 m (standing from 1.2, margin 0.6)
    q["rooty"] = rng.uniform(-0.8, 0.8)
    v["rootx"] = rng.uniform(-1, 10)  # walk from 1 m/s, run from 8
    v["rootz"] = rng.uniform(-1, 1)


@pytest.mark.parametrize("task", TASKS)
def test_observation_and_reward_match_dm_control(task):
    compare("walker", task)
    compare("walker", task, state=standing)


def test_initial_states_follow_the_suite():
    arena = jarena.build_arena("dmc|domain:walker,task:walk")
    states, infos = resets(arena, 32)
    model = arena.dynamics.render.model
    qpos, qvel = np.asarray(states.physics.qpos), np.asarray(states.physics.qvel)
    np.testing.assert_array_equal(qpos[:, :2], 0)  # rootz, rootx kept
    assert np.abs(qpos[:, 2]).max() <= np.pi and qpos[:, 2].min() < -2 and qpos[:, 2].max() > 2  # pitch over the circle
    low, high = model.jnt_range[3:].T
    assert np.all((qpos[:, 3:] >= low) & (qpos[:, 3:] <= high))
    assert np.all(qpos[:, 3:].std(0) > 0.2 * (high - low) / np.sqrt(12))  # spread over the ranges
    np.testing.assert_array_equal(qvel, 0)
    compare_resets(arena, "walker", "walk", states, infos)
    assert_suite_episodes(arena, "walker", "walk")


def test_mjx_step_matches_mujoco():
    """Control steps (10 physics steps each) with floor contacts: state, observation and reward as dm_control's."""
    arena = jarena.build_arena("dmc|domain:walker,task:walk")
    params = arena.default_params()
    env = dm_env("walker", "walk", 0)
    env.reset()
    for _ in range(30):  # fall onto the floor
        env.step(np.zeros(6))
    assert env.physics.data.ncon > 0
    data = to_mjx(arena.dynamics.render.model, env.physics)

    @jax.jit
    def step(d, u):
        d = arena.dynamics.step(d, u, params.dynamics)
        return d, arena.sensor.observe(d, params.sensor), walker.reward(d, 1.0)

    rng = np.random.RandomState(0)
    for _ in range(4):
        u = rng.uniform(-1, 1, (6,)).astype(np.float32)
        expected = env.step(u)
        data, obs, reward = step(data, u)
        np.testing.assert_allclose(data.qpos, env.physics.data.qpos, atol=1e-4)
        np.testing.assert_allclose(data.qvel, env.physics.data.qvel, atol=1e-3)
        np.testing.assert_allclose(data.sensordata, env.physics.data.sensordata, atol=1e-4)  # MJX's subtreelinvel
        for k, v in expected.observation.items():
            np.testing.assert_allclose(np.asarray(obs[k]).ravel(), np.ravel(v), atol=1e-3, err_msg=k)
        np.testing.assert_allclose(reward, expected.reward, atol=1e-4)
