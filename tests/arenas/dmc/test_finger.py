import copy

import mujoco
import numpy as np
import pytest

import jarena
from jarena.arenas.dmc import common, finger
from tests.arenas.dmc.reference import (
    check_episode_length_and_timestep,
    compare,
    compare_states,
    mujoco_and_mjx_contacts,
    reset_batch,
    step_side_by_side,
)

TASKS = ["spin", "turn_easy", "turn_hard"]


def _sync(physics, model, data):
    """dm_control's per-episode target position (in its model) -> our target's mocap body."""
    data.mocap_pos[0] = physics.named.model.site_pos["target"]


def _target_to_dm(physics, data):
    physics.named.model.site_pos["target"] = data.mocap_pos[0]


def _touching(rng, physics, attempts=1000):
    """Redraws the joints until a fingertip touch sensor reads a force (about 6% of configurations)."""
    for _ in range(attempts):
        for joint in ["proximal", "distal"]:
            physics.named.data.qpos[joint] = rng.uniform(*physics.named.model.jnt_range[joint])
        physics.named.data.qpos["hinge"] = rng.uniform(-np.pi, np.pi)
        physics.forward()
        if physics.named.data.sensordata[["touchtop", "touchbottom"]].max() > 0:
            return
    raise AssertionError("no touching configuration found")


def _near_goal(rng, physics):
    """A third of the states near the goal: spinning at about -15 rad/s (spin's threshold) with the
    spinner's tip turned to within about 0.1 m of the target (turn's); a third with the fingertip
    pressing on the spinner (touch sensors > 0); a third as perturbed."""
    kind = rng.randint(3)
    if kind == 0:
        physics.named.data.qvel["hinge"] = -15 + rng.uniform(-3, 3)
        hinge = physics.named.model.body_pos["spinner", [0, 2]]
        x, z = physics.named.model.site_pos["target", [0, 2]] - hinge
        # the tip, 0.13 m from the hinge, is at angle -q from upright (the hinge turns about -y)
        physics.named.data.qpos["hinge"] = -np.arctan2(x, z) + rng.uniform(-0.8, 0.8)
    elif kind == 1:
        _touching(rng, physics)


@pytest.mark.parametrize("task", TASKS)
def test_observation_and_reward_match_dm_control(task):
    touches = []

    def adjust(rng, physics):
        _near_goal(rng, physics)
        physics.forward()
        touches.append(physics.named.data.sensordata[["touchtop", "touchbottom"]].max())

    result = compare("finger", task, states_per_seed=8, sync=_sync, adjust=adjust)
    rewards = np.asarray(result["rewards"])
    assert (rewards == 1).any() and (rewards == 0).any()
    assert sum(t > 0 for t in touches) >= 3  # touch observations compared where they are not zero


def test_task_models():
    """Each task's model holds what dm_control writes into its model at episode start; the target site
    sits in a mocap body, and every edit leaves the physics as the suite's."""
    for task, damping, size in [("spin", 0.03, 0.03), ("turn_easy", 0.5, 0.07), ("turn_hard", 0.5, 0.03)]:
        model = jarena.build_arena(f"dmc|domain:finger,task:{task}").dynamics.render.model
        n = common.Names(model)
        assert model.dof_damping[n.qvel("hinge")] == damping
        assert model.site_size[n.site("target"), 0] == size
        assert model.body_mocapid[model.site_bodyid[n.site("target")]] == 0
        assert (model.site_rgba[[n.site("target"), n.site("tip")], 3] == 0).all() == (task == "spin")
    original = common.load_model("finger")
    for task in ["turn_hard", "spin"]:
        edited = common.load_model("finger", edit=finger.EDITS[task])
        if task == "spin":  # dm_control's spin physics: the suite's model with its damping set
            original = copy.copy(common.load_model("finger"))  # (not the cached model itself)
            original.dof_damping[common.Names(original).qvel("hinge")] = 0.03
        rng = np.random.RandomState(1)
        a, b, ncon = step_side_by_side(original, edited, rng, 200, qvel=rng.uniform(-5, 5, original.nv))
        assert ncon > 0  # the finger touched the spinner
        np.testing.assert_array_equal(a.qpos, b.qpos)
        np.testing.assert_array_equal(a.qvel, b.qvel)
        np.testing.assert_array_equal(a.sensordata, b.sensordata)


def test_contact_check_matches_mujoco():
    """``common.penetrating`` (MJX) agrees with MuJoCo's ``ncon > 0`` on random configurations."""
    model = common.load_model("finger", edit=finger.EDITS["turn_easy"])
    device = common.device_model("finger", edit=finger.EDITS["turn_easy"])
    rng = np.random.RandomState(0)
    qpos = np.stack([rng.uniform(*model.jnt_range[0], 96), rng.uniform(*model.jnt_range[1], 96),
                     rng.uniform(-np.pi, np.pi, 96)], axis=1)
    blank = jarena.build_arena("dmc|domain:finger,task:turn_easy").dynamics.init(None, None)
    expected, ours = mujoco_and_mjx_contacts(model, device, blank, qpos)
    assert 10 < sum(expected) < 86  # both kinds of configuration checked
    np.testing.assert_array_equal(ours, expected)


def test_initial_states_follow_the_suite():
    arena, states, infos = reset_batch("finger", "turn_easy")
    model = arena.dynamics.render.model
    qpos = np.asarray(states.physics.qpos)
    for j in range(2):  # the finger's limited hinges: uniform in their range
        low, high = model.jnt_range[j]
        assert low <= qpos[:, j].min() and qpos[:, j].max() <= high and qpos[:, j].std() > 0.25 * (high - low)
    assert qpos[:, 2].min() >= -np.pi and qpos[:, 2].max() < np.pi and qpos[:, 2].std() > 1.4
    assert not np.asarray(states.physics.qvel).any()
    data = mujoco.MjData(model)
    for i in range(len(qpos)):  # no contacts, as dm_control's rejection loop ensures
        data.qpos[:] = qpos[i]
        mujoco.mj_forward(model, data)
        assert data.ncon == 0
    target = np.asarray(states.physics.mocap_pos[:, 0])
    hinge = model.body_pos[common.Names(model).body("spinner")]
    np.testing.assert_allclose(np.linalg.norm((target - hinge)[:, [0, 2]], axis=1), 0.13, atol=1e-6)
    np.testing.assert_allclose(target[:, 1], 0)
    assert np.ptp(np.arctan2(*(target - hinge)[:, [0, 2]].T)) > 5  # target angles all around
    compare_states("finger", "turn_easy", states.physics, infos.observation, to_dm=_target_to_dm)
    np.testing.assert_array_equal(infos.success, infos.observation["dist_to_target"] <= 0)


@pytest.mark.parametrize("task", TASKS)
def test_episode_length_and_timestep_match_dm_control(task):
    check_episode_length_and_timestep("finger", task)
