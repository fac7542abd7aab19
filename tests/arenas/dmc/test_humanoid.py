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


def test_touch_sensors_can_be_left_out_without_changing_the_task():
    """``touch_sensors:false`` (Playground's humanoid): the 18 touch sensors leave the model, every other
    sensor keeps its place in sensordata, MuJoCo's dynamics are unchanged, and the arena's observation and
    reward read the same values from both models' states."""
    from mujoco import mjx

    from tests.arenas.dmc.reference import step_side_by_side

    full = jarena.build_arena("dmc|domain:humanoid,task:walk")
    lean = jarena.build_arena("dmc|domain:humanoid,task:walk,touch_sensors:false")
    a, b = full.dynamics.render.model, lean.dynamics.render.model
    touch = mujoco.mjtSensor.mjSENS_TOUCH
    assert list(a.sensor_type).count(touch) == 18 and touch not in list(b.sensor_type)
    assert b.nsensor == a.nsensor - 18 and b.nsensordata == a.nsensordata - 18
    np.testing.assert_array_equal(b.sensor_adr, a.sensor_adr[:b.nsensor])
    # 150 physics steps from qpos0: it has fallen onto the floor, so the touch sensors read forces
    da, db, contacts = step_side_by_side(a, b, np.random.RandomState(0), 150)
    assert contacts > 0 and da.sensordata[b.nsensordata:].any()
    np.testing.assert_array_equal(da.qpos, db.qpos)
    np.testing.assert_array_equal(da.qvel, db.qvel)
    np.testing.assert_array_equal(da.sensordata[:b.nsensordata], db.sensordata)
    obs_a = full.sensor.observe(mjx.put_data(a, da), None)
    obs_b = lean.sensor.observe(mjx.put_data(b, db), None)
    for k in obs_a:
        np.testing.assert_array_equal(obs_a[k], obs_b[k], err_msg=k)
    from jarena.arenas.dmc import humanoid
    assert float(humanoid.reward(mjx.put_data(a, da), 1.0)) == float(humanoid.reward(mjx.put_data(b, db), 1.0))


@pytest.mark.parametrize("arena, message", [
    ("dmc|domain:hopper,task:hop,touch_sensors:false", "'hopper' has no unread touch sensors.*humanoid"),
    ("dmc|domain:cheetah,task:run,touch_sensors:false", "'cheetah' has no unread touch sensors"),
    ("dmc|domain:humanoid,task:walk,touch_sensors:1", "touch_sensors must be true or false, got 1"),
])
def test_touch_sensors_option_refuses_domains_that_read_them(arena, message):
    with pytest.raises(ValueError, match=message):
        jarena.build_arena(arena)
