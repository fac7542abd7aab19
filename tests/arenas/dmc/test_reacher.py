import mujoco
import numpy as np
import pytest

import jarena
from jarena.arenas.dmc import common, reacher
from tests.arenas.dmc.reference import (
    check_episode_length_and_timestep,
    compare,
    compare_states,
    reset_batch,
    step_side_by_side,
)

TASKS = ["easy", "hard"]


def _sync(physics, model, data):
    """dm_control's per-episode target position (in its model) -> our target's mocap body."""
    data.mocap_pos[0] = physics.named.model.geom_pos["target"]


def _target_to_dm(physics, data):
    physics.named.model.geom_pos["target"] = data.mocap_pos[0]


def _near_finger(rng, physics):
    """Half the states with the target moved to within 0.08 m of the finger (in dm_control's model)."""
    if rng.rand() < 0.5:
        physics.forward()
        finger = physics.named.data.geom_xpos["finger"]
        physics.named.model.geom_pos["target", :2] = finger[:2] + rng.uniform(-0.05, 0.05, 2)


@pytest.mark.parametrize("task", TASKS)
def test_observation_and_reward_match_dm_control(task):
    result = compare("reacher", task, states_per_seed=8, sync=_sync, adjust=_near_finger)
    rewards = np.asarray(result["rewards"])
    assert (rewards == 1).any() and (rewards == 0).any()


def test_each_task_has_its_target_size_in_a_mocap_body():
    for task, size in [("easy", 0.05), ("hard", 0.015)]:
        model = jarena.build_arena(f"dmc|domain:reacher,task:{task}").dynamics.render.model
        target = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "target")
        assert model.geom_size[target, 0] == size
        assert model.body_mocapid[model.geom_bodyid[target]] == 0
        assert model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT  # the target cannot collide


def test_target_edit_keeps_the_dynamics():
    """The edited model steps exactly as the suite's (MuJoCo, random states and controls)."""
    original = common.load_model("reacher")
    edited = common.load_model("reacher", edit=reacher.EDITS["hard"])
    assert (edited.nq, edited.nv, edited.nu) == (original.nq, original.nv, original.nu)
    rng = np.random.RandomState(0)
    a, b, _ = step_side_by_side(original, edited, rng, 50, qpos=rng.uniform(-2, 2, original.nq))
    np.testing.assert_array_equal(a.qpos, b.qpos)
    np.testing.assert_array_equal(a.qvel, b.qvel)


def test_initial_states_follow_the_suite():
    arena, states, infos = reset_batch("reacher", "hard")
    qpos = np.asarray(states.physics.qpos)
    assert qpos[:, 0].min() >= -np.pi and qpos[:, 0].max() < np.pi and qpos[:, 0].std() > 1.5
    assert np.abs(qpos[:, 1]).max() <= np.deg2rad(160) and qpos[:, 1].std() > 1.2  # wrist range
    assert not np.asarray(states.physics.qvel).any()
    target = np.asarray(states.physics.mocap_pos[:, 0])
    radius = np.linalg.norm(target[:, :2], axis=1)
    assert radius.min() >= 0.05 and radius.max() < 0.2 and radius.std() > 0.03  # U[0.05, 0.2)
    assert np.ptp(np.arctan2(target[:, 0], target[:, 1])) > 5  # angles all around
    np.testing.assert_allclose(target[:, 2], 0.01)
    compare_states("reacher", "hard", states.physics, infos.observation, to_dm=_target_to_dm)
    to_target = np.linalg.norm(infos.observation["to_target"], axis=1)
    np.testing.assert_array_equal(infos.success, to_target <= 0.015 + 0.01)


@pytest.mark.parametrize("task", TASKS)
def test_episode_length_and_timestep_match_dm_control(task):
    check_episode_length_and_timestep("reacher", task)
