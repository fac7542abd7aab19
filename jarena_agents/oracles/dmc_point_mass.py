"""``oracle_dmc_point_mass``: a Cartesian spring-damper pulling the dm_control point mass to its target.

For ``dmc|domain:point_mass`` (task ``easy``, MJX physics). The oracle wants the force (N)
``F = k_p (p_target - p_mass) - k_d v_mass`` on the mass, with positions ``p`` (m) of the ``target``
and ``pointmass`` geoms from the privileged data and the mass's velocity ``v = J q_dot`` (m/s). ``J``
(3 x nv) is the geom's translational Jacobian and ``A`` (nv x nu) the joint forces per unit control, both
read from the model on the host when the agent is built (the mass hangs on slide joints and the
actuators pull on fixed tendons, so both are constant). The controls solve ``A u = J^T F`` in the least
squares sense (``u = pinv(A) J^T F``) and are clipped to [-1, 1] (0.1 N each in the suite's model).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.agent import Agent
from jarena_agents.basic import SpecState
from jarena_agents.config import make_config, unbounded
from jarena_agents.registry import register_agent

if TYPE_CHECKING:  # imported when an agent is built, to keep importing jarena_agents light
    import mujoco


@dataclasses.dataclass(frozen=True)
class DmcPointMassOracleConfig:
    """Stiffness (N/m) on the position error and damping (N s/m) on the mass's velocity."""

    k_p: float = unbounded(5.0)  # N/m: wanted force per metre of position error (target - mass)
    k_d: float = unbounded(0.3)  # N s/m: wanted braking force per m/s of the mass's velocity


@dataclasses.dataclass(frozen=True)
class Actuation:
    """From the model: the mass's translational Jacobian ``jacobian`` (3 x nv, m per unit of q), the
    joint forces per unit control ``forces`` (nv x nu, N per unit control), and the geom indices of the
    mass and the target."""

    jacobian: np.ndarray
    forces: np.ndarray
    mass_geom: int
    target_geom: int


def actuation_of(model: mujoco.MjModel) -> Actuation:
    """Reads :class:`Actuation` at the model's reference configuration: the Jacobian with
    ``mj_jacGeom``, the forces per control by applying each unit control in turn (``qfrc_actuator``).
    Raises ``ValueError`` for a model where these would vary with the state."""
    import mujoco

    constant = (np.all(model.jnt_type == mujoco.mjtJoint.mjJNT_SLIDE)
                and np.all(np.isin(model.actuator_trntype, [mujoco.mjtTrn.mjTRN_JOINT, mujoco.mjtTrn.mjTRN_TENDON])))
    if not constant:
        raise ValueError("the point-mass oracle needs slide joints and joint or tendon actuators (constant "
                         "Jacobian and actuation)")
    mass = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "pointmass")
    target = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "target")
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    jacobian = np.zeros((3, model.nv))
    mujoco.mj_jacGeom(model, data, jacobian, None, mass)
    forces = np.zeros((model.nv, model.nu))
    for i in range(model.nu):
        data.ctrl[:] = 0.0
        data.ctrl[i] = 1.0
        mujoco.mj_forward(model, data)
        forces[:, i] = data.qfrc_actuator
    return Actuation(jacobian=jacobian, forces=forces, mass_geom=int(mass), target_geom=int(target))


def feedback_gains(actuation: Actuation, cfg: DmcPointMassOracleConfig) -> tuple[np.ndarray, np.ndarray]:
    """``(G_p, G_d)``, nu x 3 and nu x nv, with ``u = G_p (p_target - p_mass) - G_d q_dot``."""
    to_controls = np.linalg.pinv(actuation.forces) @ actuation.jacobian.T  # nu x 3: controls per N
    return cfg.k_p * to_controls, cfg.k_d * to_controls @ actuation.jacobian


def control(actuation: Actuation, g_p: jax.Array, g_d: jax.Array, geom_xpos: jax.Array, qvel: jax.Array
            ) -> jax.Array:
    """Controls in [-1, 1] for one arena from its geom positions (m) and joint velocities."""
    error = geom_xpos[actuation.target_geom] - geom_xpos[actuation.mass_geom]
    return jnp.clip(g_p @ error - g_d @ qvel, -1.0, 1.0)


def make_dmc_point_mass_oracle(config=None) -> Agent:
    """The oracle for ``dmc|domain:point_mass`` (task ``easy``)."""
    from jarena.arenas.dmc import common

    cfg = make_config(DmcPointMassOracleConfig, config, agent="oracle_dmc_point_mass")
    actuation = actuation_of(common.load_model("point_mass"))
    g_p, g_d = (np.asarray(g, np.float32) for g in feedback_gains(actuation, cfg))

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def act(state, info, key, privileged):
        data = privileged.physics
        return jax.vmap(lambda xpos, qvel: control(actuation, jnp.asarray(g_p), jnp.asarray(g_d), xpos, qvel))(
            data.geom_xpos, data.qvel), state

    return Agent(name="oracle_dmc_point_mass", init=init, act=act, privileged=True, made_for=("dmc-point_mass",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_dmc_point_mass", make_dmc_point_mass_oracle, tags=("oracle",))
