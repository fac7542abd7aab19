import jax
import numpy as np
import pytest

import jarena
from tests.arenas.dmc.reference import compare, resets

TASKS = ["balance", "balance_sparse", "swingup", "swingup_sparse"]


@pytest.mark.parametrize("task", TASKS)
def test_observation_and_reward_match_dm_control(task):
    compare("cartpole", task, scale=0.05 if "sparse" in task else 0.3)


@pytest.mark.parametrize("task,upside_down", [("balance", False), ("swingup", True)])
def test_initial_states_follow_the_suite(task, upside_down):
    arena = jarena.build_arena(f"dmc|domain:cartpole,task:{task}")
    states, infos = resets(arena, 64)  # episodes 0..63
    qpos = np.asarray(states.physics.qpos)
    if upside_down:
        np.testing.assert_allclose(qpos[:, 1], np.pi, atol=0.05)
        assert np.abs(qpos[:, 0]).max() < 0.05
    else:
        assert np.abs(qpos[:, 0]).max() <= 0.1 and np.abs(qpos[:, 1]).max() <= 0.034
        assert np.abs(qpos[:, 0]).std() > 0.02  # spread over the range, not a constant
    np.testing.assert_allclose(infos.observation["position"][:, 1], np.cos(qpos[:, 1]), atol=1e-5)
    assert arena.max_episode_steps == 1000


def test_mjx_step_matches_mujoco():
    """Our control step (RK4, consistent kinematics after the step) equals dm_control's physics.step."""
    from tests.arenas.dmc.reference import dm_env, to_mjx
    arena = jarena.build_arena("dmc|domain:cartpole,task:swingup")
    env = dm_env("cartpole", "swingup", 0)
    env.reset()
    data = to_mjx(arena.dynamics.render.model, env.physics)
    step = jax.jit(lambda d, u: arena.dynamics.step(d, u, arena.default_params().dynamics))
    rng = np.random.RandomState(0)
    for _ in range(20):
        u = rng.uniform(-1, 1, (1,)).astype(np.float32)
        env.physics.set_control(u)
        env.physics.step()
        data = step(data, u)
    np.testing.assert_allclose(data.qpos, env.physics.data.qpos, atol=1e-4)
    np.testing.assert_allclose(data.qvel, env.physics.data.qvel, atol=1e-3)
    np.testing.assert_allclose(data.xmat, env.physics.data.xmat.reshape(-1, 3, 3), atol=1e-4)
