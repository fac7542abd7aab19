import mujoco
import numpy as np
import pytest
from mujoco import mjx

import jarena
from jarena.arenas.dmc import common, fish
from tests.arenas.dmc.reference import (
    assert_suite_episodes,
    compare,
    compare_resets,
    perturb,
    resets,
    step_side_by_side,
)

TASKS = ["upright", "swim"]


def copy_target(physics, model, data):
    """dm_control's target (a model geom) into our physics state (the target mocap body)."""
    data.mocap_pos[0] = physics.named.model.geom_pos["target"]


def target_to_suite(physics, data, i):
    physics.named.model.geom_pos["target"] = np.asarray(data.mocap_pos[i, 0])


def anywhere_near_target(rng, physics):
    """Any orientation (upright spans [-1, 1]), the mouth 0 to 0.15 m from the target (in_target's bound is
    0.045, its margin 0.09)."""
    perturb(rng, physics)
    quat = rng.randn(4)
    physics.named.data.qpos["root"][3:7] = quat / np.linalg.norm(quat)
    physics.forward()
    direction = rng.randn(3)
    offset = rng.uniform(0, 0.15) * direction / np.linalg.norm(direction)
    physics.named.model.geom_pos["target"] = physics.named.data.geom_xpos["mouth"] + offset


@pytest.mark.parametrize("task", TASKS)
def test_observation_and_reward_match_dm_control(task):
    compare("fish", task, sync=copy_target)
    compare("fish", task, sync=copy_target, state=anywhere_near_target)


def test_the_suite_model_needs_the_edit_and_the_edit_keeps_the_dynamics():
    """MJX cannot collide the tail's ellipsoid with the torso's box; MuJoCo never collides anything (the
    model disables constraints, so it skips collision detection), so the edit that drops every geom from
    the collision table (and makes the target a mocap body) leaves MuJoCo's trajectories as they were."""
    suite_model = common.load_model("fish")
    with pytest.raises(NotImplementedError, match="mjGEOM_ELLIPSOID, mjtGeom.mjGEOM_BOX"):
        mjx.put_model(suite_model)
    assert suite_model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    ours = fish.model()
    assert ours.nmocap == 1 and ours.nq == suite_model.nq and ours.nu == suite_model.nu
    rng = np.random.RandomState(0)
    qpos = suite_model.qpos0.copy()
    qpos[2] = 0.0  # the torso through the floor: no contact either way
    a, b, contacts = step_side_by_side(suite_model, ours, rng, 500, qpos=qpos, qvel=0.1 * rng.randn(suite_model.nv))
    assert contacts == 0
    np.testing.assert_array_equal(a.qpos, b.qpos)
    np.testing.assert_array_equal(a.qvel, b.qvel)
    np.testing.assert_array_equal(a.sensordata, b.sensordata)


@pytest.mark.parametrize("task", TASKS)
def test_initial_states_follow_the_suite(task):
    arena = jarena.build_arena(f"dmc|domain:fish,task:{task}")
    n = 32
    states, infos = resets(arena, n)
    model = arena.dynamics.render.model
    qpos, qvel = np.asarray(states.physics.qpos), np.asarray(states.physics.qvel)
    np.testing.assert_allclose(qpos[:, :3], np.broadcast_to(model.qpos0[:3], (n, 3)))  # position kept
    quat = qpos[:, 3:7]
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1, atol=1e-6)
    assert quat.min() < -0.5 and quat.max() > 0.5  # orientations all over the sphere
    joints = qpos[:, 7:]
    assert np.abs(joints).max() <= 0.2 and np.all(joints.std(0) > 0.05)
    np.testing.assert_array_equal(qvel, 0)
    target = np.asarray(states.physics.mocap_pos[:, 0])
    if task == "swim":
        assert np.abs(target[:, :2]).max() <= 0.4 and target[:, 2].min() >= 0.1 and target[:, 2].max() <= 0.3
        assert np.all(target.std(0) > 0.04)
    else:
        np.testing.assert_allclose(target, np.broadcast_to(model.body_pos[model.body("target").id], (n, 3)))
    compare_resets(arena, "fish", task, states, infos, to_suite=target_to_suite)
    assert_suite_episodes(arena, "fish", task)
