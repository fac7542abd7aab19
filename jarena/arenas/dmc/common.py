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
import jax.numpy as jnp
import mujoco
from mujoco import mjx

from jarena.arenas.dmc import randomizers
from jarena.arenas.mjx.dynamics import Names, mjx_dynamics
from jarena.core.dynamics import Dynamics
from jarena.core.task import Task

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
def load_model(domain: str, *args, edit: Callable[[str], str] | None = None,
               without_sensors: tuple[str, ...] = ()) -> mujoco.MjModel:
    """The suite's model of ``domain`` (cached), ready for MJX.

    ``edit`` may rewrite the XML first (e.g. to turn a task's target into a mocap body so that its
    per-episode position lives in the physics state). ``without_sensors`` names MJCF sensor types (e.g.
    ``("touch",)``) to leave out, as mujoco_playground's humanoid leaves out its touch sensors; every
    remaining sensor keeps its place in ``sensordata`` (a ``ValueError`` otherwise), so reads resolved on
    the full model stay valid. The energy flag, which MJX does not implement and the suite's tasks never
    read, is switched off.
    """
    xml, assets = suite_xml(domain, *args)
    if edit is not None:
        xml = edit(xml)
    if without_sensors:
        xml = _without_sensors(xml, without_sensors)
    model = mujoco.MjModel.from_xml_string(_with_contact_limits(xml), assets)
    for flag in _MJX_UNUSED_FLAGS:
        model.opt.enableflags &= ~int(flag)
    if without_sensors:
        _check_sensor_addresses(model, load_model(domain, *args, edit=edit), domain)
    _SOURCES[id(model)] = (domain, args, edit)
    return model


#: ``id(model) -> (domain, args, edit)`` of every model ``load_model`` made (they live in its cache).
_SOURCES: dict[int, tuple] = {}


def _without_sensors(xml: str, types: tuple[str, ...]) -> str:
    """``xml`` without its sensors of the MJCF types ``types``."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(xml)
    for block in root.iter("sensor"):
        for element in [e for e in block if e.tag in types]:
            block.remove(element)
    return ET.tostring(root, encoding="unicode")


def _check_sensor_addresses(model: mujoco.MjModel, full: mujoco.MjModel, domain: str) -> None:
    for i in range(model.nsensor):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SENSOR, i)
        j = mujoco.mj_name2id(full, mujoco.mjtObj.mjOBJ_SENSOR, name)
        if int(model.sensor_adr[i]) != int(full.sensor_adr[j]):
            raise ValueError(f"leaving sensors out of {domain}'s model moves sensor {name!r} in sensordata "
                             f"(from {int(full.sensor_adr[j])} to {int(model.sensor_adr[i])})")


#: MJX's contact-culling settings (custom numerics read by ``mjx.put_model``; -1: no limit).
CONTACT_LIMITS = ("max_contact_points", "max_geom_pairs")


def _with_contact_limits(xml: str) -> str:
    """``xml`` with MJX's contact-culling numerics declared as -1 (no limit, MJX's behaviour when they are
    absent), so that ``with_options`` can set them on the compiled model. Numerics are user data:
    MuJoCo's simulation is unchanged."""
    numerics = "".join(f'<numeric name="{n}" data="-1"/>' for n in CONTACT_LIMITS)
    head, sep, tail = xml.rpartition("</mujoco>")
    if not sep:
        raise ValueError("not an MJCF model: no closing </mujoco>")
    return f"{head}<custom>{numerics}</custom>{sep}{tail}"


def without_collisions_target_as_mocap(xml: str, carried: tuple[str, ...] = ()) -> str:
    """``xml`` with no geom in the collision table and its world geom ``target`` moved into a mocap body
    of the same name at the geom's position (per-episode targets then live in ``data.mocap_pos``).

    ``carried``: ElementTree paths under ``worldbody`` of elements that move with the target (e.g. its
    light), re-expressed relative to it so they stay where they were.
    """
    import xml.etree.ElementTree as ET

    root = ET.fromstring(xml)
    for geom in root.iter("geom"):
        geom.set("contype", "0")
        geom.set("conaffinity", "0")
    world = root.find("worldbody")
    target = world.find("geom[@name='target']")
    world.remove(target)
    pos = target.attrib.pop("pos")
    body = ET.SubElement(world, "body", name="target", mocap="true", pos=pos)
    body.append(target)
    for path in carried:
        element = world.find(path)
        world.remove(element)
        relative = [float(a) - float(b) for a, b in zip(element.get("pos").split(), pos.split(), strict=True)]
        element.set("pos", " ".join(str(v) for v in relative))
        body.append(element)
    return ET.tostring(root, encoding="unicode")


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


INTEGRATORS = {"euler": mujoco.mjtIntegrator.mjINT_EULER, "rk4": mujoco.mjtIntegrator.mjINT_RK4,
               "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST}


def _positive_int(name: str, value) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return value


@functools.cache
def with_options(dynamics: Dynamics, iterations: int | None = None, ls_iterations: int | None = None,
                 integrator: str | None = None, eulerdamp: bool | None = None, timestep: float | None = None,
                 max_contact_points: int | None = None, max_geom_pairs: int | None = None,
                 touch_sensors: bool | None = None, differentiable: bool | None = None) -> Dynamics:
    """``dynamics`` with MuJoCo simulation options changed (cached); ``None`` keeps the model's value.

    The suite's models allow 100 solver and 50 line-search iterations (MJX stops early at the solver's
    tolerance, but a batch waits for its slowest arena); some use RK4 and implicit Euler damping.
    mujoco_playground's versions of these models use 1-4 solver iterations, Euler, no Euler damping, a
    longer physics timestep for some (pendulum, reacher, swimmer) and MJX's contact culling: faster on MJX, less exact.

    Args:
      iterations: solver iterations (positive int).
      ls_iterations: line-search iterations (positive int).
      integrator: one of ``INTEGRATORS``.
      eulerdamp: implicit joint damping in Euler steps.
      timestep: physics timestep (s); it must divide the control timestep, which stays the suite's (the
        number of physics steps per control step changes instead).
      max_contact_points: MJX contact culling (positive int): keep only the closest this many contacts per
        collision function.
      max_geom_pairs: MJX contact culling (positive int): keep only the closest this many geom pairs per pair
        type.
      touch_sensors: ``False`` leaves the model's touch sensors out (MJX computes them from the contact
        forces every physics step; Playground's humanoid has none). Only for models that ``load_model``
        made, whose tasks never read them: the caller checks that.
      differentiable: ``True`` keeps MJX's line search as a scan so that reverse-mode gradients flow through the
        step (:func:`jarena.arenas.mjx.dynamics.mjx_dynamics`); default a while loop, the same states sooner.
    """
    from jarena.arenas.mjx.render import renderer_for
    model = dynamics.render.model
    if touch_sensors is not None and not isinstance(touch_sensors, bool):
        raise ValueError(f"touch_sensors must be true or false, got {touch_sensors!r}")
    if touch_sensors is False:
        if id(model) not in _SOURCES:
            raise ValueError(f"{dynamics.name}'s model was not loaded by load_model: cannot leave sensors out")
        if mujoco.mjtSensor.mjSENS_TOUCH not in model.sensor_type:
            raise ValueError(f"touch_sensors:false: {dynamics.name}'s model has no touch sensors")
        domain, args, edit = _SOURCES[id(model)]
        model = load_model(domain, *args, edit=edit, without_sensors=("touch",))
    model = copy.copy(model)
    for name, value in (("iterations", iterations), ("ls_iterations", ls_iterations)):
        if value is not None:
            setattr(model.opt, name, _positive_int(name, value))
    for name, value in (("max_contact_points", max_contact_points), ("max_geom_pairs", max_geom_pairs)):
        if value is not None:
            index = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name)
            if index < 0:
                raise ValueError(f"{dynamics.name}'s model has no {name} numeric (not loaded by load_model)")
            model.numeric_data[model.numeric_adr[index]] = _positive_int(name, value)
    if timestep is not None:
        if isinstance(timestep, bool) or not isinstance(timestep, (int, float)) or timestep <= 0:
            raise ValueError(f"timestep must be a positive number of seconds, got {timestep!r}")
        ratio = dynamics.timestep / timestep
        if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
            raise ValueError(f"timestep {timestep} s must divide the control timestep {dynamics.timestep:g} s")
        model.opt.timestep = float(timestep)
    if integrator is not None:
        if integrator not in INTEGRATORS:
            raise ValueError(f"unknown integrator {integrator!r}; MJX runs {', '.join(INTEGRATORS)}")
        model.opt.integrator = int(INTEGRATORS[integrator])
    if eulerdamp is not None:
        if not isinstance(eulerdamp, bool):
            raise ValueError(f"eulerdamp must be true or false, got {eulerdamp!r}")
        bit = int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP)
        model.opt.disableflags = (model.opt.disableflags & ~bit) if eulerdamp else (model.opt.disableflags | bit)
    if differentiable is not None and not isinstance(differentiable, bool):
        raise ValueError(f"differentiable must be true or false, got {differentiable!r}")
    substeps = int(round(dynamics.timestep / float(model.opt.timestep)))
    return mjx_dynamics(model, substeps, name=dynamics.name, render=renderer_for(model),
                        differentiable=bool(differentiable))


# ---------------------------------------------------------------- collision-free initial states
@functools.cache
def device_model(domain: str, *args, edit: Callable[[str], str] | None = None) -> mjx.Model:
    """``load_model(domain, *args, edit=edit)`` on MJX (cached), for tasks that query the model at reset.

    Built eagerly even when first asked for inside a trace (``jax.ensure_compile_time_eval``), so the cache
    holds concrete arrays, never a tracer of the program that happened to ask first.
    """
    with jax.ensure_compile_time_eval():
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


def suite_task(name: str, reward: Callable, initialize: Callable | None = None,
               success: Callable | None = None) -> Task:
    """A suite task as a :class:`Task`: ``reward(physics)`` on the state after every control step (the
    suite's ``get_reward``), ``success(physics)`` at reset and after every step when given (else False),
    and ``initialize`` as the suite's ``initialize_episode`` (``Task.initialize``)."""

    def reset(key, physics, outcome, params):
        return (outcome if success is None else outcome.replace(success=success(physics))), ()

    def update(state, outcome, transition, params):
        data = transition.physics
        outcome = outcome.replace(reward=outcome.reward + reward(data))
        return (outcome if success is None else outcome.replace(success=success(data))), state

    return Task(update=update, reset=reset, name=name, has_success=success is not None,
                **({} if initialize is None else {"initialize": initialize}))
