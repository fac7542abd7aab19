"""``oracle_dmc_cartpole``: energy-pumping swing-up and LQR balance for the dm_control cartpole.

For ``dmc|domain:cartpole`` (tasks ``swingup`` and ``balance``, MJX physics). The hinge angle
``theta`` (rad) is 0 upright; the cart position ``x`` is in m; the action is the control in [-1, 1]
(force = 10 N x control, the actuator's gear).

- Swing-up: with the pole's mass ``m`` (kg), hinge-to-centre-of-mass distance ``l`` (m) and inertia
  about the hinge ``I`` (kg m^2), all read from the suite's model, the pole's energy relative to resting
  upright (J) is ``E = I theta_dot^2 / 2 + m g l (cos(theta) - 1)``, and ``dE/dt = -m l cos(theta)
  theta_dot x_ddot``. Commanding ``u = k_E E theta_dot cos(theta) - k_x x - k_x_dot x_dot`` drives
  ``E`` to 0 (unsaturated and without the cart terms, ``dE/dt`` has the sign of ``-E``) while a
  spring-damper on the cart keeps it near the centre (the reward falls off with ``|x|``).
- Balance: within ``capture_angle`` of upright, ``u = -K (x, theta, x_dot, theta_dot)`` with ``K`` the
  discrete LQR gain of the model linearised about upright (:mod:`jarena_agents.oracles.lqr`),
  computed once on the host when the agent is built.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.agent import Agent
from jarena_agents.basic import SpecState
from jarena_agents.config import Range, make_config, non_negative, positive, ranged, unbounded
from jarena_agents.oracles import lqr
from jarena_agents.registry import register_agent

if TYPE_CHECKING:  # imported when an agent is built, to keep importing jarena_agents light
    import mujoco


@dataclasses.dataclass(frozen=True)
class DmcCartpoleOracleConfig:
    """Swing-up gains (control per J rad/s; per m; per m/s), the capture angle (rad) and the LQR's
    diagonal state costs on (x, theta, x_dot, theta_dot) and control cost, per control step."""

    energy_gain: float = unbounded(15.0)  # k_E of the swing-up term k_E E theta_dot cos(theta), control per J rad/s
    k_x: float = unbounded(1.5)  # swing-up: control per m of cart position (spring to the centre)
    k_x_dot: float = unbounded(1.5)  # swing-up: control per m/s of cart velocity (damper)
    capture_angle: float = ranged(0.6, Range(0, math.pi))  # rad: LQR balance within this angle of upright
    q_x: float = non_negative(1.0)  # LQR state cost on the cart position (per m^2, per control step)
    q_theta: float = non_negative(10.0)  # LQR state cost on the pole angle (per rad^2)
    q_x_dot: float = non_negative(0.1)  # LQR state cost on the cart velocity (per (m/s)^2)
    q_theta_dot: float = non_negative(0.1)  # LQR state cost on the pole angular velocity (per (rad/s)^2)
    r: float = positive(1.0)  # LQR cost on the control (per control^2, control in [-1, 1])


@dataclasses.dataclass(frozen=True)
class Pole:
    """The pole's physics from the model: mass (kg), hinge-to-COM distance (m), inertia about the
    hinge (kg m^2), gravity (m/s^2), and the qpos/qvel addresses of the slider and the hinge."""

    mass: float
    com: float
    inertia: float
    gravity: float
    slider: int
    hinge: int


def pole_of(model: mujoco.MjModel) -> Pole:
    """Reads :class:`Pole` from the suite's cartpole model (its first pole)."""
    import mujoco

    slider = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "slider")
    hinge = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "hinge_1")
    body = int(model.jnt_bodyid[hinge])
    axis = model.jnt_axis[hinge]  # in the body frame, through the body's origin
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.body_iquat[body])
    rot = rot.reshape(3, 3)  # inertial frame -> body frame
    i_com = axis @ rot @ np.diag(model.body_inertia[body]) @ rot.T @ axis
    ipos = model.body_ipos[body]
    lever = ipos - (ipos @ axis) * axis
    mass = float(model.body_mass[body])
    return Pole(mass=mass, com=float(np.linalg.norm(lever)), inertia=float(i_com + mass * lever @ lever),
                gravity=float(np.linalg.norm(model.opt.gravity)), slider=int(model.jnt_qposadr[slider]),
                hinge=int(model.jnt_qposadr[hinge]))


def upright_gain(model: mujoco.MjModel, cfg: DmcCartpoleOracleConfig) -> np.ndarray:
    """The LQR gain K (1 x 4) on (x, theta, x_dot, theta_dot) about upright at rest, for one control step
    (one physics step of the suite's model)."""
    a, b = lqr.linearise(model, np.zeros(model.nq))
    q = np.diag([cfg.q_x, cfg.q_theta, cfg.q_x_dot, cfg.q_theta_dot])
    return lqr.lqr_gain(a, b, q, np.array([[cfg.r]]))


def _wrap(angle):
    return (angle + jnp.pi) % (2 * jnp.pi) - jnp.pi


def pole_energy(pole: Pole, theta, theta_dot):
    """The pole's energy (J) relative to resting upright, in the cart's frame."""
    return 0.5 * pole.inertia * theta_dot**2 + pole.mass * pole.gravity * pole.com * (jnp.cos(theta) - 1.0)


def control(pole: Pole, gain: jax.Array, cfg: DmcCartpoleOracleConfig, qpos: jax.Array, qvel: jax.Array):
    """The control in [-1, 1] for one arena from its joint positions and velocities."""
    x, x_dot = qpos[pole.slider], qvel[pole.slider]
    theta, theta_dot = _wrap(qpos[pole.hinge]), qvel[pole.hinge]
    energy = pole_energy(pole, theta, theta_dot)
    pump = cfg.energy_gain * energy * theta_dot * jnp.cos(theta) - cfg.k_x * x - cfg.k_x_dot * x_dot
    balance = -gain @ jnp.stack([x, theta, x_dot, theta_dot])
    u = jnp.where(jnp.abs(theta) < cfg.capture_angle, balance[0], pump)
    return jnp.clip(u, -1.0, 1.0)[None]


def make_dmc_cartpole_oracle(config=None) -> Agent:
    """The oracle for ``dmc|domain:cartpole`` (tasks ``swingup``, ``balance``)."""
    from jarena.arenas.dmc import common

    cfg = make_config(DmcCartpoleOracleConfig, config, agent="oracle_dmc_cartpole")
    model = common.load_model("cartpole")
    pole = pole_of(model)
    gain = np.asarray(upright_gain(model, cfg), np.float32)

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def act(state, info, key, privileged):
        data = privileged.physics
        return jax.vmap(lambda qpos, qvel: control(pole, jnp.asarray(gain), cfg, qpos, qvel))(
            data.qpos, data.qvel), state

    return Agent(name="oracle_dmc_cartpole", init=init, act=act, privileged=True, made_for=("dmc-cartpole",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_dmc_cartpole", make_dmc_cartpole_oracle, tags=("oracle",))
