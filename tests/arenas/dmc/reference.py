"""Compare a dmc arena's observation and reward with dm_control's own task code on the same states.

States are set in dm_control's physics (qpos, qvel, ctrl, plus any task-specific model state via
``sync``), forwarded with MuJoCo, copied into our model's MjData and put on MJX; our sensor and task
then run on that ``mjx.Data`` (no MJX step is compiled, so these tests are cheap on the CPU).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax
import mujoco
import numpy as np
import pytest
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
            sync: Callable | None = None, atol: float = 1e-4, state: Callable | None = None,
            adjust: Callable | None = None) -> dict:
    """Asserts equal observations (every key) and rewards on random states of the task.

    ``state(rng, physics)``, when given, sets dm_control's state instead of :func:`perturb` (e.g. a walker
    standing and moving, where the reward's terms are not constant); ``adjust(rng, physics)``, if given,
    then edits it (e.g. to bring it near the goal so that sparse rewards are exercised). The physics is
    forwarded afterwards. Returns the largest absolute deviation seen per observation key and for
    ``"reward"``, and the rewards seen (``"rewards"``: dm_control's, in order).
    """
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
    deviation = {}
    rewards = []
    for seed in seeds:
        env = dm_env(domain, task, seed)
        env.reset()
        rng = np.random.RandomState(seed)
        for _ in range(states_per_seed):
            if state is None:
                perturb(rng, env.physics, scale)
            else:
                state(rng, env.physics)
            if adjust is not None:
                adjust(rng, env.physics)
            env.physics.forward()
            expected_obs = env.task.get_observation(env.physics)
            expected_reward = env.task.get_reward(env.physics)
            obs, reward = ours(to_mjx(model, env.physics, sync))
            assert set(obs) == set(expected_obs), f"observation keys {sorted(obs)} != {sorted(expected_obs)}"
            for k, v in expected_obs.items():
                assert obs[k].shape == env.observation_spec()[k].shape, f"{domain}/{task} observation {k} shape"
                assert obs[k].dtype == np.float32, f"{domain}/{task} observation {k} dtype"
                np.testing.assert_allclose(np.asarray(obs[k]).ravel(), np.asarray(v, np.float64).ravel(),
                                           atol=atol, rtol=1e-4, err_msg=f"{domain}/{task} observation {k}")
            np.testing.assert_allclose(float(reward), float(expected_reward), atol=atol, rtol=1e-4,
                                       err_msg=f"{domain}/{task} reward")
            for k, v in expected_obs.items():
                err = float(np.max(np.abs(np.asarray(obs[k], np.float64).ravel() - np.asarray(v, np.float64).ravel())))
                deviation[k] = max(deviation.get(k, 0.0), err)
            deviation["reward"] = max(deviation.get("reward", 0.0), abs(float(reward) - float(expected_reward)))
            rewards.append(float(expected_reward))
            checked += 1
    assert checked == len(list(seeds)) * states_per_seed
    return {**deviation, "rewards": rewards}


def reset_batch(domain: str, task: str, n: int = 64):
    """``(arena, states, infos)`` of episodes 0..n-1, stacked (:func:`resets`: the states of
    ``jarena.batch_reset(arena, None, n, episodes=range(n))`` from an unbatched reset, which compiles faster)."""
    arena = jarena.build_arena(f"dmc|domain:{domain},task:{task}")
    states, infos = resets(arena, n)
    return arena, states, infos


def compare_states(domain: str, task: str, physics, observations, *, to_dm: Callable | None = None,
                   count: int = 8, atol: float = 1e-4) -> float:
    """Asserts that dm_control observes ``observations`` (a batch, e.g. of resets computed on MJX) on the
    batch's first ``count`` states ``physics`` (an ``mjx.Data`` batch): qpos and qvel are copied into
    dm_control's physics, ``to_dm(physics_dm, data_i)`` copies task state kept elsewhere (mocap targets
    into the model), then dm_control forwards. Returns the largest absolute deviation.
    """
    env = dm_env(domain, task, 0)
    env.reset()
    worst = 0.0
    for i in range(count):
        data_i = jax.tree.map(lambda x: np.asarray(x[i]), physics)
        env.physics.data.qpos[:] = data_i.qpos
        env.physics.data.qvel[:] = data_i.qvel
        if to_dm is not None:
            to_dm(env.physics, data_i)
        env.physics.forward()
        for k, v in env.task.get_observation(env.physics).items():
            ours = np.asarray(observations[k][i], np.float64)
            np.testing.assert_allclose(ours.ravel(), np.asarray(v, np.float64).ravel(), atol=atol, rtol=1e-4,
                                       err_msg=f"{domain}/{task} observation {k} of reset state {i}")
            worst = max(worst, float(np.max(np.abs(ours.ravel() - np.asarray(v, np.float64).ravel()))))
    return worst


def check_episode_length_and_timestep(domain: str, task: str) -> None:
    """``arena.max_episode_steps`` and the dynamics' timestep equal dm_control's step limit and control
    timestep for the task."""
    arena = jarena.build_arena(f"dmc|domain:{domain},task:{task}")
    env = dm_env(domain, task, 0)
    assert arena.max_episode_steps == env._step_limit
    assert np.isclose(arena.dynamics.timestep, env.control_timestep(), rtol=1e-9, atol=0)
    assert arena.dynamics.render.model.opt.timestep == env.physics.model.opt.timestep


def compare_sensors(domain: str, task: str, sensors: Sequence[str], *, state: Callable | None = None,
                    sync: Callable | None = None, seeds=range(2), states_per_seed: int = 4, atol: float = 1e-4,
                    rtol: float = 1e-4) -> None:
    """Asserts that MJX computes the named sensors as MuJoCo does on random states.

    MuJoCo's forwarded state is put on MJX with its sensor data zeroed; MJX recomputes the kinematics,
    centre-of-mass and velocity quantities and its position and velocity sensors, and, where a sensor
    needs the acceleration stage (touch), its acceleration sensors from MuJoCo's contact forces. Only
    small pieces of MJX are compiled (no collision detection, no constraint solver).
    """
    arena = jarena.build_arena(f"dmc|domain:{domain},task:{task}")
    model = arena.dynamics.render.model
    m = mjx.put_model(model)
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, name) for name in sensors]
    assert min(ids) >= 0, f"unknown sensors in {sensors}"
    needs_acc = any(model.sensor_needstage[i] == mujoco.mjtStage.mjSTAGE_ACC for i in ids)

    @jax.jit
    def recompute(d):
        d = d.replace(sensordata=jax.numpy.zeros_like(d.sensordata))
        d = mjx.com_vel(m, mjx.com_pos(m, mjx.kinematics(m, d)))
        d = mjx.sensor_vel(m, mjx.sensor_pos(m, d))
        return mjx.sensor_acc(m, d).sensordata if needs_acc else d.sensordata

    for seed in seeds:
        env = dm_env(domain, task, seed)
        env.reset()
        rng = np.random.RandomState(seed)
        for _ in range(states_per_seed):
            if state is None:
                perturb(rng, env.physics)
            else:
                state(rng, env.physics)
            env.physics.forward()
            ours = np.asarray(recompute(to_mjx(model, env.physics, sync)))
            for name, i in zip(sensors, ids, strict=True):
                at = slice(model.sensor_adr[i], model.sensor_adr[i] + model.sensor_dim[i])
                np.testing.assert_allclose(ours[at], env.physics.named.data.sensordata[name], atol=atol, rtol=rtol,
                                           err_msg=f"{domain} sensor {name}")


def compare_resets(arena, domain: str, task: str, states, infos, *, to_suite: Callable | None = None,
                   atol: float = 1e-4, rtol: float = 1e-4) -> None:
    """Asserts that every reset's observation equals dm_control's on the same physics state.

    Each batched state's qpos and qvel (and, via ``to_suite(physics, data, i)``, task-specific model state
    such as a target) are written into dm_control's physics, which runs its ``after_reset``; the suite's
    ``get_observation`` must then give our reset observation. Checks the MJX forward pass of the reset
    (kinematics, sensors, contact forces) against MuJoCo's.
    """
    env = dm_env(domain, task, 0)
    env.reset()
    physics = env.physics
    qpos, qvel = np.asarray(states.physics.qpos), np.asarray(states.physics.qvel)
    for i in range(qpos.shape[0]):
        with physics.reset_context():
            physics.data.qpos[:] = qpos[i]
            physics.data.qvel[:] = qvel[i]
            if to_suite is not None:
                to_suite(physics, states.physics, i)
        expected = env.task.get_observation(physics)
        assert set(infos.observation) == set(expected)
        for k, v in expected.items():
            np.testing.assert_allclose(np.asarray(infos.observation[k][i]).ravel(), np.asarray(v).ravel(), atol=atol,
                                       rtol=rtol, err_msg=f"{domain}/{task} reset {i} observation {k}")


def assert_suite_episodes(arena, domain: str, task: str) -> None:
    """Episode length in control steps and control timestep as dm_control's environment has them."""
    env = dm_env(domain, task, 0)
    assert arena.max_episode_steps == env._step_limit
    assert arena.dynamics.timestep == pytest.approx(env.control_timestep())


def resets(arena, n: int):
    """Episodes ``0..n-1``'s ``(state, info)`` stacked along a leading axis, from one jitted ``arena.reset``.

    The same states as ``jarena.batch_reset(arena, None, n, episodes=range(n))`` (to the bit, or within a few
    float32 ulps where vmap rounds differently: finger, reacher, pendulum); an unbatched reset compiles in
    about 60% of the batched one's time, which is most of these tests' cost on the CPU.
    """
    reset = jax.jit(lambda episode: arena.reset(None, None, episode))
    return jax.tree.map(lambda *leaves: np.stack(leaves), *[reset(np.int32(e)) for e in range(n)])


def step_side_by_side(original: mujoco.MjModel, edited: mujoco.MjModel, rng: np.random.RandomState, steps: int,
                      qpos=None, qvel=None) -> tuple[mujoco.MjData, mujoco.MjData, int]:
    """Steps both models with MuJoCo from the same state (``qpos``/``qvel``, default the model's) under the
    same random controls in [-1, 1]; returns both datas and the original's contacts summed over the steps,
    for tests that an XML edit leaves the dynamics unchanged."""
    a, b = mujoco.MjData(original), mujoco.MjData(edited)
    if qpos is not None:
        a.qpos[:] = b.qpos[:] = qpos
    if qvel is not None:
        a.qvel[:] = b.qvel[:] = qvel
    contacts = 0
    for _ in range(steps):
        a.ctrl[:] = b.ctrl[:] = rng.uniform(-1, 1, original.nu)
        mujoco.mj_step(original, a)
        mujoco.mj_step(edited, b)
        contacts += a.ncon
    return a, b, contacts


def mujoco_and_mjx_contacts(model: mujoco.MjModel, device: mjx.Model, blank: mjx.Data, qpos: np.ndarray
                            ) -> tuple[list[bool], np.ndarray]:
    """For each row of ``qpos`` (N, nq): MuJoCo's ``ncon > 0`` after ``mj_forward``, and
    ``common.penetrating`` on MJX from ``blank`` with that qpos."""
    from jarena.arenas.dmc import common
    data = mujoco.MjData(model)
    expected = []
    for q in qpos:
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        expected.append(data.ncon > 0)
    ours = jax.jit(jax.vmap(lambda q: common.penetrating(device, blank.replace(qpos=q))))(qpos)
    return expected, np.asarray(ours)
