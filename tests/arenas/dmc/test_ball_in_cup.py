import mujoco
import numpy as np

import jarena
from jarena.arenas.dmc import common
from tests.arenas.dmc.reference import (
    check_episode_length_and_timestep,
    compare,
    compare_states,
    mujoco_and_mjx_contacts,
    reset_batch,
)


def _ball_near_cup(rng, physics):
    """Half the states with the ball within 0.04 m of the cup's target site (in: within 0.025 m)."""
    if rng.rand() < 0.5:
        physics.forward()
        offset = physics.named.data.site_xpos["target", [0, 2]] - physics.named.data.xpos["ball", [0, 2]]
        physics.named.data.qpos[["ball_x", "ball_z"]] += offset + rng.uniform(-0.04, 0.04, 2)


def test_observation_and_reward_match_dm_control():
    result = compare("ball_in_cup", "catch", states_per_seed=8, adjust=_ball_near_cup)
    rewards = np.asarray(result["rewards"])
    assert (rewards == 1).any() and (rewards == 0).any()


def test_contact_check_matches_mujoco():
    """``common.penetrating`` (MJX) agrees with MuJoCo's ``ncon > 0`` on the suite's ball placements."""
    arena = jarena.build_arena("dmc|domain:ball_in_cup,task:catch")
    model = arena.dynamics.render.model
    rng = np.random.RandomState(0)
    qpos = np.zeros((200, 4))
    qpos[:, 2], qpos[:, 3] = rng.uniform(-0.2, 0.2, 200), rng.uniform(0.2, 0.5, 200)
    blank = arena.dynamics.init(None, None)
    expected, ours = mujoco_and_mjx_contacts(model, common.device_model("ball_in_cup"), blank, qpos)
    assert 5 < sum(expected) < 195  # both kinds of placement checked
    np.testing.assert_array_equal(ours, expected)


def test_initial_states_follow_the_suite():
    arena, states, infos = reset_batch("ball_in_cup", "catch")
    model = arena.dynamics.render.model
    qpos = np.asarray(states.physics.qpos)
    assert not qpos[:, :2].any()  # the cup at its origin
    assert qpos[:, 2].min() >= -0.2 and qpos[:, 2].max() < 0.2 and qpos[:, 2].std() > 0.08  # U[-.2, .2)
    assert qpos[:, 3].min() >= 0.2 and qpos[:, 3].max() < 0.5 and qpos[:, 3].std() > 0.06  # U[.2, .5)
    assert not np.asarray(states.physics.qvel).any()
    data = mujoco.MjData(model)
    for q in qpos:  # no contacts, as dm_control's rejection loop ensures
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        assert data.ncon == 0
    compare_states("ball_in_cup", "catch", states.physics, infos.observation)
    # success: the ball's centre (0.2 m above its joints' origin) within 0.025 m of the target (0.55 m up)
    inside = (np.abs(qpos[:, 2]) < 0.025) & (np.abs(qpos[:, 3] + 0.2 - 0.55) < 0.025)
    np.testing.assert_array_equal(infos.success, inside)


def test_episode_length_and_timestep_match_dm_control():
    check_episode_length_and_timestep("ball_in_cup", "catch")
