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


@functools.cache
def with_solver(dynamics: Dynamics, iterations: int | None = None, ls_iterations: int | None = None) -> Dynamics:
    """``dynamics`` with the constraint solver's iteration limits changed (cached).

    The suite's models allow 100 solver and 50 line-search iterations; MJX stops early at the solver's
    tolerance, but batched arenas wait for the slowest. Fewer iterations (mujoco_playground uses 1-4 and
    4-8) trade contact accuracy for speed.
    """
    from jarena.arenas.mjx.render import renderer_for
    model = copy.copy(dynamics.render.model)
    for name, value in (("iterations", iterations), ("ls_iterations", ls_iterations)):
        if value is not None:
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
            setattr(model.opt, name, value)
    substeps = int(round(dynamics.timestep / float(model.opt.timestep)))
    return mjx_dynamics(model, substeps, name=dynamics.name, render=renderer_for(model))
