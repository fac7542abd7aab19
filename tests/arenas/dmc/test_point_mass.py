import numpy as np

from tests.arenas.dmc.reference import check_episode_length_and_timestep, compare, compare_states, reset_batch


def _near_target(rng, physics):
    """Half the states within 0.03 m of the target (radius 0.015 m, margin 0.015 m)."""
    if rng.rand() < 0.5:
        physics.data.qpos[:] = rng.uniform(-0.02, 0.02, 2)


def test_observation_and_reward_match_dm_control():
    result = compare("point_mass", "easy", states_per_seed=8, adjust=_near_target)
    rewards = np.asarray(result["rewards"])
    assert (rewards > 0.8).any() and (rewards < 0.1).any()


def test_initial_states_follow_the_suite():
    arena, states, infos = reset_batch("point_mass", "easy")
    qpos = np.asarray(states.physics.qpos)
    assert np.abs(qpos).max() <= 0.29  # the joints' range
    assert np.all(qpos.std(0) > 0.12)  # uniform on +-0.29: std 0.167
    assert not np.asarray(states.physics.qvel).any()
    compare_states("point_mass", "easy", states.physics, infos.observation)


def test_episode_length_and_timestep_match_dm_control():
    check_episode_length_and_timestep("point_mass", "easy")
