import mujoco
import numpy as np
import pytest

import jarena
from tests.arenas.dmc.reference import assert_suite_episodes, compare, compare_resets, perturb, resets

TASKS = ["stand", "walk", "run"]


def standing(rng, physics):
    """Standing near the target head height (1.4 m, margin 0.35), tilted up to 70 degrees (upright from
    cos = 0.9), its centre of mass moving at 0 to 17 m/s (stand: still; walk 1; run 10)."""
    perturb(rng, physics, 0.05)
    q = physics.data.qpos
    q[:7] = physics.model.qpos0[:7]
    q[2] += rng.uniform(-0.6, 0.1)
    axis = rng.randn(3)
    angle = rng.uniform(0, 1.2)
    q[3:7] = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis / np.linalg.norm(axis)])
    physics.data.qvel[:2] = rng.uniform(-1, 1, 2) * rng.choice([0.5, 2.0, 12.0])


@pytest.mark.parametrize("task", TASKS)
def test_observation_and_reward_match_dm_control(task):
    compare("humanoid", task)
    compare("humanoid", task, state=standing)


def test_initial_states_do_not_penetrate():
    """Random joints re-drawn until no contact: MuJoCo finds none in any start (dm_control's ``ncon == 0``)."""
    arena = jarena.build_arena("dmc|domain:humanoid,task:stand")
    n = 32
    states, infos = resets(arena, n)
    model = arena.dynamics.render.model
    qpos, qvel = np.asarray(states.physics.qpos), np.asarray(states.physics.qvel)
    data = mujoco.MjData(model)
    for q in qpos:
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        assert data.ncon == 0
    np.testing.assert_allclose(qpos[:, :3], np.broadcast_to(model.qpos0[:3], (n, 3)))  # root position kept
    np.testing.assert_allclose(np.linalg.norm(qpos[:, 3:7], axis=1), 1, atol=1e-6)
    assert np.all(qpos[:, 3:7] >= 0)  # dm_control's orientation: a normalised uniform [0, 1)^4 draw
    low, high = model.jnt_range[1:].T
    assert np.all((qpos[:, 7:] >= low) & (qpos[:, 7:] <= high))
    assert np.all(qpos[:, 7:].std(0) > 0.2 * (high - low) / np.sqrt(12))
    np.testing.assert_array_equal(qvel, 0)
    compare_resets(arena, "humanoid", "stand", states, infos)
    assert_suite_episodes(arena, "humanoid", "stand")
