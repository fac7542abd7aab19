import mujoco
import numpy as np
import pytest

import jarena
from tests.arenas.dmc.reference import assert_suite_episodes, compare, compare_resets, compare_sensors, perturb, resets

TASKS = ["stand", "hop"]


def upright(rng, physics):
    """Near upright, legs from straight to crouched (torso-foot height around 0.6), the foot mostly in the
    floor (touch sensors on), moving forward at up to 4 m/s (hop from 2 m/s, margin 1)."""
    perturb(rng, physics, 0.05)
    q, v = physics.named.data.qpos, physics.named.data.qvel
    crouch = {"waist": (-0.3, 0.3), "hip": (-1.2, 0.1), "knee": (0.1, 2.4), "ankle": (-0.7, 0.7)}
    for joint, (low, high) in crouch.items():
        q[joint] = rng.uniform(low, high)
    q["rooty"] = rng.uniform(-0.3, 0.3)
    v["rootx"] = rng.uniform(-1, 4)
    physics.forward()
    foot = physics.named.data
    axis = foot.geom_xmat["foot"].reshape(3, 3)[:, 2] * physics.named.model.geom_size["foot", 1]
    lowest = min(foot.geom_xpos["foot", 2] + axis[2], foot.geom_xpos["foot", 2] - axis[2])
    lowest -= physics.named.model.geom_size["foot", 0]
    q["rootz"] -= lowest + rng.uniform(-0.02, 0.05)  # the foot's lowest point 2 cm above the floor to 5 cm in it


@pytest.mark.parametrize("task", TASKS)
def test_observation_and_reward_match_dm_control(task):
    compare("hopper", task)
    compare("hopper", task, state=upright)


def test_mjx_computes_speed_and_touch_sensors():
    """MJX's subtree velocity and touch sensors (normal contact forces in the toe and heel zones) equal MuJoCo's."""
    compare_sensors("hopper", "hop", ["torso_subtreelinvel", "touch_toe", "touch_heel"], state=upright,
                    states_per_seed=6)


def test_initial_states_follow_the_suite():
    arena = jarena.build_arena("dmc|domain:hopper,task:hop")
    n = 32
    states, infos = resets(arena, n)
    model = arena.dynamics.render.model
    qpos, qvel = np.asarray(states.physics.qpos), np.asarray(states.physics.qvel)
    np.testing.assert_array_equal(qpos[:, :2], 0)  # rootx, rootz kept
    assert np.abs(qpos[:, 2]).max() <= np.pi and qpos[:, 2].min() < -2 and qpos[:, 2].max() > 2  # pitch
    low, high = model.jnt_range[3:].T
    assert np.all((qpos[:, 3:] >= low) & (qpos[:, 3:] <= high))
    assert np.all(qpos[:, 3:].std(0) > 0.2 * (high - low) / np.sqrt(12))
    np.testing.assert_array_equal(qvel, 0)
    # As in the suite (unlike its humanoid), starts in contact are kept: about 17% (the leg in the torso).
    data = mujoco.MjData(model)
    touching = 0
    for q in qpos:
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        touching += data.ncon > 0
    assert 0 < touching < n
    compare_resets(arena, "hopper", "hop", states, infos)
    assert_suite_episodes(arena, "hopper", "hop")
