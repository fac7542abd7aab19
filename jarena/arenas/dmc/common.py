"""Shared pieces of the DeepMind Control Suite domains: models, physics reads, domain assembly.

Models come from the ``dm_control`` package's suite assets, loaded when an arena is built (never at
import). Every domain's dynamics step is one dm_control *control* step (``n_sub_steps`` physics steps),
its tasks compute rewards on the state after the step, and episodes last ``time_limit`` seconds, as in
``dm_control.rl.control.Environment``.
"""

from __future__ import annotations

import copy
import functools
import importlib
import importlib.util
from collections.abc import Callable
from pathlib import Path

import jax
import mujoco
from mujoco import mjx

from jarena.arenas.dmc import randomizers
from jarena.arenas.mjx.dynamics import Names, mjx_dynamics
from jarena.core.dynamics import Dynamics

#: MuJoCo features that MJX does not implement and that the suite's models use only for reporting.
_MJX_UNUSED_FLAGS = (mujoco.mjtEnableBit.mjENBL_ENERGY,)


_COMMON_ASSETS = ("./common/materials.xml", "./common/skybox.xml", "./common/visual.xml")


def suite_dir() -> Path:
    """The directory of dm_control's suite files (found without importing dm_control)."""
    spec = importlib.util.find_spec("dm_control")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("the dmc arenas need dm_control's suite models: pip install 'dm-control==1.0.50'")
    return Path(next(iter(spec.submodule_search_locations))) / "suite"


def suite_xml(domain: str, *args) -> tuple[str, dict]:
    """``(xml, assets)`` of the suite's ``domain``, as ``dm_control.suite.<domain>.get_model_and_assets(*args)``.

    Plain models are read from their XML files, so only dm_control's model files need be present;
    generated models (``args`` given, e.g. a swimmer's number of links) use the suite's own code.
    """
    if args:
        module = importlib.import_module(f"dm_control.suite.{domain}")
        xml, assets = module.get_model_and_assets(*args)
        return (xml.decode() if isinstance(xml, bytes) else xml), assets
    root = suite_dir()
    path = root / f"{domain}.xml"
    if not path.exists():
        raise FileNotFoundError(f"dm_control has no suite model {path.name} (in {root})")
    return path.read_text(), {name: (root / name).read_bytes() for name in _COMMON_ASSETS}


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


INTEGRATORS = {"euler": mujoco.mjtIntegrator.mjINT_EULER, "rk4": mujoco.mjtIntegrator.mjINT_RK4,
               "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST}


@functools.cache
def with_options(dynamics: Dynamics, iterations: int | None = None, ls_iterations: int | None = None,
                 integrator: str | None = None, eulerdamp: bool | None = None) -> Dynamics:
    """``dynamics`` with MuJoCo simulation options changed (cached); ``None`` keeps the model's value.

    The suite's models allow 100 solver and 50 line-search iterations (MJX stops early at the solver's
    tolerance, but a batch waits for its slowest arena); some use RK4 and implicit Euler damping.
    mujoco_playground's versions of these models use 1-4 solver iterations, Euler and no Euler damping:
    faster on MJX, less exact. Args: ``iterations`` and ``ls_iterations`` (positive ints),
    ``integrator`` (one of ``INTEGRATORS``), ``eulerdamp`` (implicit joint damping in Euler steps).
    """
    from jarena.arenas.mjx.render import renderer_for
    model = copy.copy(dynamics.render.model)
    for name, value in (("iterations", iterations), ("ls_iterations", ls_iterations)):
        if value is not None:
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
            setattr(model.opt, name, value)
    if integrator is not None:
        if integrator not in INTEGRATORS:
            raise ValueError(f"unknown integrator {integrator!r}; MJX runs {', '.join(INTEGRATORS)}")
        model.opt.integrator = int(INTEGRATORS[integrator])
    if eulerdamp is not None:
        if not isinstance(eulerdamp, bool):
            raise ValueError(f"eulerdamp must be true or false, got {eulerdamp!r}")
        bit = int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP)
        model.opt.disableflags = (model.opt.disableflags & ~bit) if eulerdamp else (model.opt.disableflags | bit)
    substeps = int(round(dynamics.timestep / float(model.opt.timestep)))
    return mjx_dynamics(model, substeps, name=dynamics.name, render=renderer_for(model))
