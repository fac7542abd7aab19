import mujoco
import numpy as np
import pytest
from mujoco import mjx

import jarena
from jarena.arenas.dmc import common, swimmer
from tests.arenas.dmc.reference import (
    assert_suite_episodes,
    compare,
    compare_resets,
    compare_sensors,
    perturb,
    resets,
    step_side_by_side,
)


def copy_target(physics, model, data):
    """dm_control's target (a model geom) into our physics state (the target mocap body)."""
    data.mocap_pos[0] = physics.named.model.geom_pos["target"]


def target_to_suite(physics, data, i):
    physics.named.model.geom_pos["target"] = np.asarray(data.mocap_pos[i, 0])


def near_target(rng, physics):
    """The nose 0 to 0.8 m from the target (the reward's radius is 0.1, its margin 0.5)."""
    perturb(rng, physics)
    physics.forward()
    direction = rng.uniform(0, 2 * np.pi)
    offset = rng.uniform(0, 0.8) * np.array([np.cos(direction), np.sin(direction)])
    physics.named.model.geom_pos["target"][:2] = physics.named.data.geom_xpos["nose"][:2] + offset


def test_observation_and_reward_match_dm_control():
    compare("swimmer", "swimmer6", sync=copy_target)
    compare("swimmer", "swimmer6", sync=copy_target, state=near_target)


def test_mjx_computes_the_body_velocity_sensors():
    velocities = ["head_vel", "head_gyro"] + [f"{kind}_{i}" for i in range(5) for kind in ("velocimeter", "gyro")]
    compare_sensors("swimmer", "swimmer6", velocities, sync=copy_target)


def test_the_suite_model_needs_the_edit_and_the_edit_keeps_the_dynamics():
    """MJX cannot collide the head's ellipsoid with the segments' boxes; MuJoCo never collides them (the
    model disables contacts), so the edit that drops every geom from the collision table (and makes the
    target a mocap body) leaves MuJoCo's trajectories exactly as they were."""
    suite_model = common.load_model("swimmer", 6)
    with pytest.raises(NotImplementedError, match="mjGEOM_ELLIPSOID, mjtGeom.mjGEOM_BOX"):
        mjx.put_model(suite_model)
    assert suite_model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    ours = swimmer.model()
    assert ours.nmocap == 1 and ours.nq == suite_model.nq and ours.nu == suite_model.nu
    rng = np.random.RandomState(0)
    a, b, _ = step_side_by_side(suite_model, ours, rng, 500, qpos=suite_model.qpos0 + 0.5 * rng.randn(suite_model.nq),
                                qvel=rng.randn(suite_model.nv))
    np.testing.assert_array_equal(a.qpos, b.qpos)
    np.testing.assert_array_equal(a.qvel, b.qvel)
    np.testing.assert_array_equal(a.sensordata, b.sensordata)


def test_initial_states_follow_the_suite():
    arena = jarena.build_arena("dmc|domain:swimmer,task:swimmer6")
    n = 64
    states, infos = resets(arena, n)
    model = arena.dynamics.render.model
    qpos, qvel = np.asarray(states.physics.qpos), np.asarray(states.physics.qvel)
    np.testing.assert_array_equal(qpos[:, :2], 0)  # position kept
    assert np.abs(qpos[:, 2]).max() <= np.pi and qpos[:, 2].min() < -2 and qpos[:, 2].max() > 2  # heading
    limit = np.deg2rad(60)
    assert np.abs(qpos[:, 3:]).max() <= limit + 1e-6 and np.all(qpos[:, 3:].std(0) > 0.2 * limit)
    np.testing.assert_array_equal(qvel, 0)
    target = np.asarray(states.physics.mocap_pos[:, 0])
    np.testing.assert_allclose(target[:, 2], model.body_pos[model.body("target").id, 2])
    assert np.abs(target[:, :2]).max() <= 2 and np.abs(target[:, :2]).max() > 1.5
    close = np.all(np.abs(target[:, :2]) <= 0.3, axis=1).mean()  # 0.2 close + 0.8 * (0.3 / 2)^2 far ones
    assert 0.08 < close < 0.4
    compare_resets(arena, "swimmer", "swimmer6", states, infos, to_suite=target_to_suite)
    assert_suite_episodes(arena, "swimmer", "swimmer6")
