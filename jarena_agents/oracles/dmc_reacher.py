"""``oracle_dmc_reacher``: inverse kinematics plus joint PD control for the dm_control reacher.

For ``dmc|domain:reacher`` (tasks ``easy`` and ``hard``, MJX physics). The arm is planar: the shoulder
(free hinge, angle ``q1``, rad) at the ``arm`` body's origin, a link of length ``l1`` (m) to the wrist
(hinge ``q2``, limited to its range, +-160 deg in the suite), a link of ``l2`` to the finger; the
lengths, limits and inertias are read from the suite's model when the agent is built.

Each step the oracle places the finger on the target (the ``target`` mocap body, privileged):

- IK: ``q2 = +-acos((r^2 - l1^2 - l2^2) / (2 l1 l2))`` for the target at distance ``r`` (clipped to the
  reachable annulus), ``q1 = atan2(y, x) - atan2(l2 sin q2, l1 + l2 cos q2)``; of the two elbow
  solutions the one within the wrist's range needing the least joint travel (shoulder error wrapped to
  [-pi, pi)) is taken, its wrist angle clipped to the range.
- PD: torque ``tau_i = M_ii (w^2 e_i - 2 zeta w q_dot_i)`` (N m) per joint, with ``M_ii`` (kg m^2) the
  joint's inertia with the arm stretched, ``w`` the natural frequency (rad/s) and ``zeta`` the damping
  ratio; control = torque / gear (N m per unit control), clipped to [-1, 1].
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.agent import Agent
from jarena_agents.basic import SpecState
from jarena_agents.config import make_config, non_negative, positive
from jarena_agents.registry import register_agent

if TYPE_CHECKING:  # imported when an agent is built, to keep importing jarena_agents light
    import mujoco


@dataclasses.dataclass(frozen=True)
class DmcReacherOracleConfig:
    """Closed-loop natural frequency (rad/s) and damping ratio of each joint's PD control."""

    natural_frequency: float = positive(30.0)  # w (rad/s): joint torque M_ii (w^2 e_i - 2 zeta w q_dot_i)
    damping_ratio: float = non_negative(1.0)  # zeta of that torque (1: critically damped)


@dataclasses.dataclass(frozen=True)
class Arm:
    """The arm from the model: link lengths (m), wrist range (rad), joint inertias with the arm
    stretched (kg m^2), the gears (N m per unit control) and indices of the actuators driving the
    shoulder and the wrist, the number of actuators, and the addresses of the joints, the shoulder body
    and the target's mocap slot."""

    l1: float
    l2: float
    wrist_range: tuple[float, float]
    inertia: tuple[float, float]
    gear: tuple[float, float]
    actuators: tuple[int, int]
    nu: int
    qpos: tuple[int, int]
    qvel: tuple[int, int]
    shoulder_body: int
    target_mocap: int


def arm_of(model: mujoco.MjModel) -> Arm:
    """Reads :class:`Arm` from the reacher model (its joints ``shoulder``, ``wrist``, bodies ``arm``,
    ``hand``, ``finger``, actuators on the two joints and a mocap body ``target``)."""
    import mujoco

    def idx(kind, name):
        return mujoco.mj_name2id(model, kind, name)

    joints = [idx(mujoco.mjtObj.mjOBJ_JOINT, n) for n in ("shoulder", "wrist")]
    hand, finger = (idx(mujoco.mjtObj.mjOBJ_BODY, n) for n in ("hand", "finger"))
    data = mujoco.MjData(model)  # qpos = 0: the arm stretched along the shoulder's x axis
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    dofs = [int(model.jnt_dofadr[j]) for j in joints]
    actuators = [int(np.flatnonzero((model.actuator_trnid[:, 0] == j)
                                    & (model.actuator_trntype == mujoco.mjtTrn.mjTRN_JOINT))[0]) for j in joints]
    target = int(model.body_mocapid[idx(mujoco.mjtObj.mjOBJ_BODY, "target")])
    return Arm(l1=float(np.linalg.norm(model.body_pos[hand][:2])), l2=float(np.linalg.norm(model.body_pos[finger][:2])),
               wrist_range=tuple(float(v) for v in model.jnt_range[joints[1]]),
               inertia=tuple(float(full[d, d]) for d in dofs),
               gear=tuple(float(model.actuator_gear[a, 0]) for a in actuators), actuators=tuple(actuators),
               nu=int(model.nu),
               qpos=tuple(int(model.jnt_qposadr[j]) for j in joints), qvel=tuple(dofs),
               shoulder_body=idx(mujoco.mjtObj.mjOBJ_BODY, "arm"), target_mocap=target)


def _wrap(angle):
    return (angle + jnp.pi) % (2 * jnp.pi) - jnp.pi


def forward_kinematics(arm: Arm, q: jax.Array) -> jax.Array:
    """The finger's x, y (m) relative to the shoulder for joint angles ``q = (q1, q2)``."""
    return (arm.l1 * jnp.stack([jnp.cos(q[0]), jnp.sin(q[0])])
            + arm.l2 * jnp.stack([jnp.cos(q[0] + q[1]), jnp.sin(q[0] + q[1])]))


def inverse_kinematics(arm: Arm, target: jax.Array, q: jax.Array) -> jax.Array:
    """Joint angles (q1, q2) placing the finger at ``target`` (x, y relative to the shoulder, m): the
    elbow solution nearest the current angles ``q``, with q1 in [-pi, pi) and q2 within the wrist range."""
    r = jnp.clip(jnp.linalg.norm(target), abs(arm.l1 - arm.l2) + 1e-6, arm.l1 + arm.l2 - 1e-6)
    cos_q2 = jnp.clip((r**2 - arm.l1**2 - arm.l2**2) / (2 * arm.l1 * arm.l2), -1.0, 1.0)
    q2 = jnp.clip(jnp.stack([1.0, -1.0]) * jnp.arccos(cos_q2), *arm.wrist_range)  # both elbows
    q1 = _wrap(jnp.arctan2(target[1], target[0])
               - jnp.arctan2(arm.l2 * jnp.sin(q2), arm.l1 + arm.l2 * jnp.cos(q2)))
    travel = jnp.abs(_wrap(q1 - q[0])) + jnp.abs(q2 - q[1])
    best = jnp.argmin(travel)
    return jnp.stack([q1[best], q2[best]])


def control(arm: Arm, cfg: DmcReacherOracleConfig, qpos: jax.Array, qvel: jax.Array, shoulder: jax.Array,
            target: jax.Array) -> jax.Array:
    """Controls in [-1, 1] for the two actuators of one arena (``shoulder``, ``target``: world x, y, m)."""
    q = jnp.stack([qpos[arm.qpos[0]], qpos[arm.qpos[1]]])
    q_dot = jnp.stack([qvel[arm.qvel[0]], qvel[arm.qvel[1]]])
    goal = inverse_kinematics(arm, target - shoulder, q)
    error = jnp.stack([_wrap(goal[0] - q[0]), goal[1] - q[1]])
    w, zeta = cfg.natural_frequency, cfg.damping_ratio
    torque = jnp.asarray(arm.inertia) * (w**2 * error - 2 * zeta * w * q_dot)
    ctrl = jnp.clip(torque / jnp.asarray(arm.gear), -1.0, 1.0)
    return jnp.zeros(arm.nu, ctrl.dtype).at[jnp.asarray(arm.actuators)].set(ctrl)


def make_dmc_reacher_oracle(config=None) -> Agent:
    """The oracle for ``dmc|domain:reacher`` (tasks ``easy``, ``hard``: their arms are the same)."""
    from jarena.arenas.dmc import reacher

    cfg = make_config(DmcReacherOracleConfig, config, agent="oracle_dmc_reacher")
    arm = arm_of(reacher.names("easy").model)

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def act(state, info, key, privileged):
        data = privileged.physics
        return jax.vmap(lambda qpos, qvel, xpos, mocap: control(
            arm, cfg, qpos, qvel, xpos[arm.shoulder_body, :2], mocap[arm.target_mocap, :2]))(
            data.qpos, data.qvel, data.xpos, data.mocap_pos), state

    return Agent(name="oracle_dmc_reacher", init=init, act=act, privileged=True, made_for=("dmc-reacher",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_dmc_reacher", make_dmc_reacher_oracle, tags=("oracle",))
