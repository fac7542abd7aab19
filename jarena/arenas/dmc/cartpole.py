"""dm_control ``cartpole``: balance, balance_sparse, swingup, swingup_sparse.

- Physics: MJX on the suite's ``cartpole.xml`` (RK4, 0.01 s; one physics step per control step).
- Control: ``Box(-1, 1, (1,))``, force on the cart.
- Observation: ``position`` (3,) = cart x, cos and sin of the pole angle (``xmat`` zz, xz);
  ``velocity`` (2,) = qvel.
- Reward (smooth): ``upright * centered * small_control * small_velocity``; sparse: 1 when the cart is
  within +-0.25 and the pole's cosine is >= 0.995. Success: the sparse criterion holds.
- Episodes: 10 s = 1000 steps; balance starts near upright, swingup hanging down.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jarena.arenas.dmc import common
from jarena.arenas.domain import Domain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.task import Task
from jarena.tasks.tolerance import tolerance

_TIME_LIMIT = 10.0
_CART_RANGE = (-0.25, 0.25)
_ANGLE_COSINE_RANGE = (0.995, 1.0)
_POLE = 2  # first pole body


def dynamics() -> Dynamics:
    return common.domain_dynamics("cartpole", 1)


def cart_position(data):
    return data.qpos[0]


def pole_angle_cosine(data):
    return common.xmat_entry(data, slice(_POLE, None), "zz")


def observe(data, params):
    position = jnp.concatenate([data.qpos[:1], jnp.stack([common.xmat_entry(data, slice(_POLE, None), "zz"),
                                                          common.xmat_entry(data, slice(_POLE, None), "xz")],
                                                         axis=-1).ravel()])
    return {"position": position.astype(jnp.float32), "velocity": data.qvel.astype(jnp.float32)}


def sensor() -> Sensor:
    return Sensor(observe=observe, name="dmc-cartpole")


def reward(data, sparse: bool) -> jax.Array:
    """The suite's ``Balance._get_reward`` on the state after a step."""
    if sparse:
        cart_in_bounds = tolerance(cart_position(data), _CART_RANGE)
        angle_in_bounds = tolerance(pole_angle_cosine(data), _ANGLE_COSINE_RANGE).prod()
        return cart_in_bounds * angle_in_bounds
    upright = (pole_angle_cosine(data) + 1) / 2
    centered = (1 + tolerance(cart_position(data), margin=2)) / 2
    small_control = (4 + tolerance(data.ctrl, margin=1, value_at_margin=0, sigmoid="quadratic")[0]) / 5
    small_velocity = (1 + tolerance(data.qvel[1:], margin=5).min()) / 2
    return upright.mean() * small_control * small_velocity * centered


def _success(data):
    return (tolerance(cart_position(data), _CART_RANGE) * tolerance(pole_angle_cosine(data), _ANGLE_COSINE_RANGE).prod()
            ) > 0


def _balance(swing_up: bool, sparse: bool, name: str) -> Task:
    def initialize(key, data, dynamics_params, params):
        k_slider, k_hinge, k_rest, k_vel = jax.random.split(key, 4)
        nv = data.qvel.shape[0]
        qpos = data.qpos
        if swing_up:
            qpos = qpos.at[0].set(0.01 * jax.random.normal(k_slider))
            qpos = qpos.at[1].set(jnp.pi + 0.01 * jax.random.normal(k_hinge))
            qpos = qpos.at[2:].set(0.1 * jax.random.normal(k_rest, (nv - 2,)))
        else:
            qpos = qpos.at[0].set(jax.random.uniform(k_slider, (), minval=-0.1, maxval=0.1))
            qpos = qpos.at[1:].set(jax.random.uniform(k_hinge, (nv - 1,), minval=-0.034, maxval=0.034))
        return data.replace(qpos=qpos, qvel=0.01 * jax.random.normal(k_vel, (nv,)))

    return common.suite_task(name, lambda data: reward(data, sparse), initialize, success=_success)


def balance() -> Task:
    return _balance(False, False, "balance")


def balance_sparse() -> Task:
    return _balance(False, True, "balance_sparse")


def swingup() -> Task:
    return _balance(True, False, "swingup")


def swingup_sparse() -> Task:
    return _balance(True, True, "swingup_sparse")


DOMAIN = Domain(name="cartpole", dynamics=dynamics, sensor=sensor,
                tasks={"balance": balance, "balance_sparse": balance_sparse, "swingup": swingup,
                       "swingup_sparse": swingup_sparse},
                time_limit=common.steps(_TIME_LIMIT, 0.01), auto_reset="lazy",
                tags={t: ("benchmark",) for t in ("balance", "balance_sparse", "swingup", "swingup_sparse")})
