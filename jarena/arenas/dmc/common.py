"""Shared pieces of the DeepMind Control Suite domains: models, physics reads, domain assembly.

Models come from the ``dm_control`` package's suite assets, loaded when an arena is built (never at
import). Every domain's dynamics step is one dm_control *control* step (``n_sub_steps`` physics steps),
its tasks compute rewards on the state after the step, and episodes last ``time_limit`` seconds, as in
``dm_control.rl.control.Environment``.
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Callable

import jax
import jax.numpy as jnp
import mujoco
from mujoco import mjx

from jarena.arenas.dmc import randomizers
from jarena.arenas.mjx.dynamics import Names, mjx_dynamics
from jarena.core.dynamics import Dynamics

#: MuJoCo features that MJX does not implement and that the suite's models use only for reporting.
_MJX_UNUSED_FLAGS = (mujoco.mjtEnableBit.mjENBL_ENERGY,)


def suite_xml(domain: str, *args) -> tuple[str, dict]:
    """``(xml, assets)`` of ``dm_control.suite.<domain>.get_model_and_assets(*args)``."""
    try:
        module = importlib.import_module(f"dm_control.suite.{domain}")
    except ImportError as e:
        raise ImportError(f"the dmc arenas need dm_control's suite models: pip install 'dm-control==1.0.50' ({e})"
                          ) from None
    xml, assets = module.get_model_and_assets(*args)
    return (xml.decode() if isinstance(xml, bytes) else xml), assets


@functools.cache
def load_model(domain: str, *args, edit: Callable[[str], str] | None = None) -> mujoco.MjModel:
    """The suite's model of ``domain`` (cached), ready for MJX.

    ``edit`` may rewrite the XML first (e.g. to turn a task's target into a mocap body so that its
    per-episode position lives in the physics state). The energy flag, which MJX does not implement and
    the suite's tasks never read, is switched off.
    """
    xml, assets = suite_xml(domain, *args)
    if edit is not None:
        xml = edit(xml)
    model = mujoco.MjModel.from_xml_string(xml, assets)
    for flag in _MJX_UNUSED_FLAGS:
        model.opt.enableflags &= ~int(flag)
    return model


def replace_once(xml: str, old: str, new: str) -> str:
    """``xml`` with its single occurrence of ``old`` replaced by ``new`` (for ``edit`` functions); a
    ``ValueError`` if ``old`` does not occur exactly once (the suite's model changed)."""
    count = xml.count(old)
    if count != 1:
        raise ValueError(f"expected one occurrence of {old!r} in the suite's model, found {count}")
    return xml.replace(old, new)


@functools.cache
def domain_dynamics(domain: str, n_sub_steps: int, *args, edit: Callable[[str], str] | None = None) -> Dynamics:
    """MJX dynamics of ``domain``'s model with a control step of ``n_sub_steps`` physics steps (cached)."""
    from jarena.arenas.mjx.render import renderer_for
    model = load_model(domain, *args, edit=edit)
    return mjx_dynamics(model, n_sub_steps, name=f"dmc-{domain}", render=renderer_for(model))


@functools.cache
def names(domain: str, *args, edit: Callable[[str], str] | None = None) -> Names:
    return Names(load_model(domain, *args, edit=edit))


def steps(time_limit: float, control_timestep: float) -> int:
    """Number of control steps in ``time_limit`` seconds (dm_control's step limit)."""
    return int(round(time_limit / control_timestep))


# ---------------------------------------------------------------- reads of the physics state (mjx.Data)
def xmat_entry(data: mjx.Data, body: int | slice, entry: str) -> jax.Array:
    """dm_control's ``named.data.xmat[body, 'zz']``: entry ``'xz'`` is row x, column z of the body frame."""
    axes = "xyz"
    return data.xmat[body, axes.index(entry[0]), axes.index(entry[1])]


def randomize_limited_and_rotational_joints(key: jax.Array, model: mujoco.MjModel, qpos: jax.Array) -> jax.Array:
    """See :func:`jarena.arenas.dmc.randomizers.randomize_limited_and_rotational_joints`."""
    return randomizers.randomize_limited_and_rotational_joints(key, model, qpos)


# ---------------------------------------------------------------- collision-free initial states
@functools.cache
def device_model(domain: str, *args, edit: Callable[[str], str] | None = None) -> mjx.Model:
    """``load_model(domain, *args, edit=edit)`` on MJX (cached), for tasks that query the model at reset."""
    return mjx.put_model(load_model(domain, *args, edit=edit))


def penetrating(m: mjx.Model, data: mjx.Data) -> jax.Array:
    """dm_control's ``physics.data.ncon > 0`` after ``after_reset`` for ``data.qpos``: any contact.

    Runs MJX's kinematics and collision detection only; MJX keeps a fixed set of candidate contacts, of
    which MuJoCo would report those closer than their margin (the suite's models have no geom gap).
    """
    data = mjx.collision(m, mjx.kinematics(m, data))
    contact = data._impl.contact
    if contact.dist.size == 0:
        return jnp.zeros((), bool)
    return jnp.any(contact.dist < contact.includemargin)


def sample_collision_free(key: jax.Array, data: mjx.Data, sample: Callable[[jax.Array, mjx.Data], mjx.Data],
                          m: mjx.Model, max_attempts: int = 1000) -> mjx.Data:
    """dm_control's rejection loops (``while penetrating: randomise``): ``sample(key, data)`` with fresh
    keys until the state has no contact, at most ``max_attempts`` draws (dm_control raises after that;
    here the last draw is kept). A ``lax.while_loop``: batched resets draw until every member is free.
    """
    def draw(carry):
        attempt, key, _, _ = carry
        key, k = jax.random.split(key)
        new = sample(k, data)
        return attempt + 1, key, new, penetrating(m, new)

    def again(carry):
        attempt, _, _, bad = carry
        return bad & (attempt < max_attempts)

    # starts "penetrating", so the loop draws at least once (and traces ``sample`` and the check once)
    return jax.lax.while_loop(again, draw, (jnp.zeros((), jnp.int32), key, data, jnp.ones((), bool)))[2]
