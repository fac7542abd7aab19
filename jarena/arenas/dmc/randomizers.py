"""``dm_control.suite.utils.randomizers`` in JAX: random joint configurations for episode starts."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco


def axis_angle_quaternion(axis: jax.Array, angle: jax.Array) -> jax.Array:
    """Unit quaternion (w, x, y, z) rotating by ``angle`` radians about unit ``axis`` (mju_axisAngle2Quat)."""
    return jnp.concatenate([jnp.cos(angle / 2)[None], axis * jnp.sin(angle / 2)])


def random_limited_quaternion(key: jax.Array, limit: float) -> jax.Array:
    """A rotation about a uniformly random axis by an angle uniform in [0, ``limit``)."""
    k_axis, k_angle = jax.random.split(key)
    axis = jax.random.normal(k_axis, (3,))
    return axis_angle_quaternion(axis / jnp.linalg.norm(axis), jax.random.uniform(k_angle) * limit)


def randomize_limited_and_rotational_joints(key: jax.Array, model: mujoco.MjModel, qpos: jax.Array) -> jax.Array:
    """Randomises ``qpos`` (nq,) as dm_control does (same rules and distributions, JAX random numbers).

    - limited hinges and slides: uniform in their range; limited balls: ``random_limited_quaternion``;
    - unlimited hinges: uniform in [-pi, pi]; unlimited balls: uniform on the unit 3-sphere;
    - free joints: orientation from a normalised uniform [0, 1)^4 draw (as dm_control, which keeps it
      for benchmark continuity), position kept.
    """
    for j in range(model.njnt):
        k = jax.random.fold_in(key, j)
        kind = mujoco.mjtJoint(int(model.jnt_type[j]))
        adr = int(model.jnt_qposadr[j])
        low, high = (float(v) for v in model.jnt_range[j])
        if model.jnt_limited[j]:
            if kind in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
                qpos = qpos.at[adr].set(jax.random.uniform(k, (), minval=low, maxval=high))
            elif kind == mujoco.mjtJoint.mjJNT_BALL:
                qpos = qpos.at[adr:adr + 4].set(random_limited_quaternion(k, high))
        elif kind == mujoco.mjtJoint.mjJNT_HINGE:
            qpos = qpos.at[adr].set(jax.random.uniform(k, (), minval=-jnp.pi, maxval=jnp.pi))
        elif kind == mujoco.mjtJoint.mjJNT_BALL:
            quat = jax.random.normal(k, (4,))
            qpos = qpos.at[adr:adr + 4].set(quat / jnp.linalg.norm(quat))
        elif kind == mujoco.mjtJoint.mjJNT_FREE:
            quat = jax.random.uniform(k, (4,))
            qpos = qpos.at[adr + 3:adr + 7].set(quat / jnp.linalg.norm(quat))
    return qpos
