"""Compare a dmc arena's observation and reward with dm_control's own task code on the same states.

States are set in dm_control's physics (qpos, qvel, ctrl, plus any task-specific model state via
``sync``), forwarded with MuJoCo, copied into our model's MjData and put on MJX; our sensor and task
then run on that ``mjx.Data`` (no MJX step is compiled, so these tests are cheap on the CPU).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import mujoco
import numpy as np
from dm_control import suite
from mujoco import mjx

import jarena
from jarena.core.types import Outcome, Transition


def dm_env(domain: str, task: str, seed: int):
    return suite.load(domain, task, task_kwargs={"random": seed})


def perturb(rng: np.random.RandomState, physics, scale: float = 0.3) -> None:
    """Random qpos/qvel/ctrl around the state dm_control reset to (quaternions kept normalised)."""
    m = physics.model
    physics.data.qpos[:] = physics.data.qpos + scale * rng.randn(m.nq)
    for j in range(m.njnt):  # renormalise free and ball joint quaternions
        adr = m.jnt_qposadr[j]
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            q = physics.data.qpos[adr + 3:adr + 7]
            physics.data.qpos[adr + 3:adr + 7] = q / np.linalg.norm(q)
        elif m.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
            q = physics.data.qpos[adr:adr + 4]
            physics.data.qpos[adr:adr + 4] = q / np.linalg.norm(q)
    physics.data.qvel[:] = scale * 3 * rng.randn(m.nv)
    low, high = m.actuator_ctrlrange.T
    physics.data.ctrl[:] = rng.uniform(low * 1.2, high * 1.2)  # includes out-of-range controls
    physics.forward()


def to_mjx(model: mujoco.MjModel, physics, sync: Callable | None = None) -> mjx.Data:
    """Our model's state equal to dm_control's ``physics``, forwarded, on MJX."""
    data = mujoco.MjData(model)
    data.qpos[:] = physics.data.qpos
    data.qvel[:] = physics.data.qvel
    data.ctrl[:] = physics.data.ctrl
    if model.na:
        data.act[:] = physics.data.act
    if sync is not None:
        sync(physics, model, data)
    mujoco.mj_forward(model, data)
    return mjx.put_data(model, data)


def compare(domain: str, task: str, *, seeds=range(3), states_per_seed: int = 4, scale: float = 0.3,
            sync: Callable | None = None, atol: float = 1e-4) -> None:
    """Asserts equal observations (every key) and rewards on random states of the task."""
    arena = jarena.build_arena(f"dmc|domain:{domain},task:{task}")
    params = arena.default_params()
    model = arena.dynamics.render.model  # the MjModel our dynamics were built from

    @jax.jit
    def ours(data):
        _, task_state = arena.task.reset(jax.random.key(0), data, Outcome.empty(), params.task)
        outcome, _ = arena.task.update(task_state, Outcome.empty(),
                                       Transition(data, data.ctrl, data, params.dynamics), params.task)
        return arena.sensor.observe(data, params.sensor), outcome.reward

    checked = 0
    for seed in seeds:
        env = dm_env(domain, task, seed)
        env.reset()
        rng = np.random.RandomState(seed)
        for _ in range(states_per_seed):
            perturb(rng, env.physics, scale)
            expected_obs = env.task.get_observation(env.physics)
            expected_reward = env.task.get_reward(env.physics)
            obs, reward = ours(to_mjx(model, env.physics, sync))
            assert set(obs) == set(expected_obs), f"observation keys {sorted(obs)} != {sorted(expected_obs)}"
            for k, v in expected_obs.items():
                np.testing.assert_allclose(np.asarray(obs[k]).ravel(), np.asarray(v, np.float64).ravel(),
                                           atol=atol, rtol=1e-4, err_msg=f"{domain}/{task} observation {k}")
            np.testing.assert_allclose(float(reward), float(expected_reward), atol=atol, rtol=1e-4,
                                       err_msg=f"{domain}/{task} reward")
            checked += 1
    assert checked == len(list(seeds)) * states_per_seed
