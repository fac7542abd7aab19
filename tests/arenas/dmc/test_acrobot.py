import numpy as np
import pytest

from tests.arenas.dmc.reference import check_episode_length_and_timestep, compare, compare_states, reset_batch

TASKS = ["swingup", "swingup_sparse"]


def _near_upright(rng, physics):
    """Half the states with both arms within ~0.15 rad of upright: the tip within about the target's
    0.2 m radius of it, on both sides of the boundary."""
    if rng.rand() < 0.5:
        physics.named.data.qpos[["shoulder", "elbow"]] = rng.uniform(-0.15, 0.15, 2)


@pytest.mark.parametrize("task", TASKS)
def test_observation_and_reward_match_dm_control(task):
    result = compare("acrobot", task, states_per_seed=8, adjust=_near_upright)
    rewards = np.asarray(result["rewards"])
    assert (rewards == 1).any() and (rewards < 1).any()  # inside and outside the target compared
    if task == "swingup":
        assert ((rewards > 0.05) & (rewards < 1)).any()  # and the smooth margin


def test_initial_states_follow_the_suite():
    arena, states, infos = reset_batch("acrobot", "swingup")
    qpos = np.asarray(states.physics.qpos)
    assert qpos.min() >= -np.pi and qpos.max() < np.pi
    assert np.all((qpos.std(0) > 1.5) & (qpos.std(0) < 2.1))  # uniform on [-pi, pi): std 1.81
    assert abs(np.corrcoef(qpos.T)[0, 1]) < 0.35  # independent draws
    assert not np.asarray(states.physics.qvel).any()
    compare_states("acrobot", "swingup", states.physics, infos.observation)


@pytest.mark.parametrize("task", TASKS)
def test_episode_length_and_timestep_match_dm_control(task):
    check_episode_length_and_timestep("acrobot", task)
