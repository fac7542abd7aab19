"""A Brax environment's pieces as jarena dynamics, sensor and task (imports Brax; built on demand).

- Physics state: Brax's own ``brax.envs.State`` (``pipeline_state``, ``obs``, ``reward``, ``done``,
  ``metrics``, ``info``). ``init(key, params)`` is ``env.reset(key)``, ``step(physics, control, params)``
  is ``env.step(physics, control)``: one Brax env step (``n_frames`` pipeline steps, ``env.dt`` seconds).
- Control: ``Box(-1, 1, (env.action_size,))``. Brax's envs take actions in [-1, 1]: most pass them to
  actuators whose ``ctrlrange`` is [-1, 1]; humanoid, pusher and inverted_pendulum map [-1, 1] onto
  their wider or narrower ``ctrlrange`` themselves. Out-of-range actions are handled as Brax does (the
  physics clips the control to ``ctrlrange``; control costs see the action as given).
- Observation: ``{"state": physics.obs}``, Brax's observation vector (float32).
- Task ``brax``: Brax's reward; ``terminated`` is Brax's ``done`` (e.g. ant or hopper unhealthy; Brax's
  envs never truncate, episodes end by jarena's ``time_limit``); Brax's ``metrics`` (named scalars such
  as ``x_velocity``, ``reward_ctrl``) become ``Outcome.metrics``.
- Params (:class:`BraxParams`): mass and friction scales applied to the env's ``System`` inside
  ``init`` and ``step``, for domain randomisation (1 = Brax's model). Every backend reads them, but the
  spring and positional pipelines use ``mass ** (1 - spring_mass_scale)``: where a model sets
  ``spring_mass_scale=1`` (ant), masses, and so ``mass_scale``, have no effect on those two.
"""

from __future__ import annotations

import copy
import functools
import importlib
import inspect
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.mjx.dynamics import while_line_search
from jarena.core import faults
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.spec import Box
from jarena.core.task import Task
from jarena.core.tree import as_float32

#: Envs that rescale their [-1, 1] action onto the actuators' ``ctrlrange`` inside ``step`` (Brax 0.14.2:
#: humanoid.py, pusher.py, inverted_pendulum.py); the others pass actions to [-1, 1] actuators.
RESCALING_ENVS = frozenset({"humanoid", "pusher", "inverted_pendulum"})

#: Constructor arguments of Brax's ``PipelineEnv`` that envs forward through ``**kwargs``.
_PIPELINE_OPTIONS = ("n_frames",)


@struct.dataclass
class BraxParams:
    """Scales of the Brax model's physical constants (1 = Brax's own values); vmap over them to randomise.

    Attributes:
      mass_scale: multiplies every body's mass and rotational inertia.
      friction_scale: multiplies every geom's friction coefficients.
    """

    mass_scale: jax.Array = 1.0
    friction_scale: jax.Array = 1.0


def apply_params(sys, params: BraxParams):
    """``sys`` (a ``brax.System``) with ``params``' scales applied (traceable).

    Scales both copies of the inertial constants a ``System`` holds: ``link.inertia`` (read by the
    generalized, positional and spring pipelines) and ``body_mass``/``body_inertia`` (read by MJX).
    """
    inertia = sys.link.inertia
    inertia = inertia.replace(mass=inertia.mass * params.mass_scale, i=inertia.i * params.mass_scale)
    return sys.replace(link=sys.link.replace(inertia=inertia),
                       body_mass=sys.body_mass * params.mass_scale,
                       body_inertia=sys.body_inertia * params.mass_scale,
                       geom_friction=sys.geom_friction * params.friction_scale)


def env_class(path: str) -> type:
    """The env class at ``module:Class`` (e.g. ``brax.envs.ant:Ant``)."""
    module, cls = path.split(":")
    return getattr(importlib.import_module(module), cls)


def env_options(path: str) -> list[str]:
    """Keyword arguments of the env class at ``path`` that an arena string may set (not ``backend``)."""
    params = inspect.signature(env_class(path).__init__).parameters.values()
    own = [p.name for p in params if p.name not in ("self", "backend")
           and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    return own + [o for o in _PIPELINE_OPTIONS if o not in own]


@functools.cache
def _make_env(path: str, backend: str, options: tuple[tuple[str, Any], ...]):
    return env_class(path)(backend=backend, **dict(options))


def make_env(path: str, backend: str, **options):
    """The env class at ``path`` built with ``backend`` and ``options`` (cached per arguments).

    The same as ``brax.envs.get_environment(name, backend=backend, **options)``.
    """
    return _make_env(path, backend, tuple(sorted(options.items())))


def _with_params(env, params: BraxParams):
    """A shallow copy of ``env`` stepping ``params``' system (the shared env is never mutated)."""
    env = copy.copy(env)
    env.sys = apply_params(env.sys, params)
    return env


def _raw_key(key: jax.Array) -> jax.Array:
    """Brax's envs take raw ``uint32[2]`` keys (``jax.random.PRNGKey``)."""
    return jax.random.key_data(key) if jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key) else key


def _strong(x) -> jax.Array:
    x = jnp.asarray(x)
    return jax.lax.convert_element_type(x, x.dtype) if x.weak_type else x


def _typed(state):
    """Brax's state with reward, done and metrics as float32 arrays and no weakly typed leaves.

    Envs return Python floats and weakly typed arrays in places (inverted_pendulum's ``info["time_out"]``
    is weak after ``step``, not after ``reset``); a state whose types change from step to step would make
    ``jit`` retrace and ``lax.scan`` reject its carry.
    """
    f32 = lambda x: jnp.asarray(x, jnp.float32)
    state = state.replace(reward=f32(state.reward), done=f32(state.done),
                          metrics={k: f32(v) for k, v in state.metrics.items()})
    return jax.tree_util.tree_map(_strong, state)


def brax_dynamics(env, name: str = "brax") -> Dynamics:
    """Dynamics stepping Brax env ``env`` (a ``PipelineEnv``); the physics state is Brax's ``State``."""

    def init(key, params):
        return _typed(_with_params(env, params).reset(_raw_key(key)))

    def step(physics, control, params):
        # Brax's envs update ``state.metrics`` in place; give them copies so that the caller's state
        # (e.g. a transition's ``previous``) keeps its own.
        physics = physics.replace(metrics=dict(physics.metrics), info=dict(physics.info))
        with while_line_search():  # the mjx backend: MJX's states or within rounding, sooner (jarena.arenas.mjx)
            return _typed(_with_params(env, params).step(physics, jnp.asarray(control, jnp.float32)))

    size = int(env.action_size)
    return Dynamics(init=init, step=step, control_spec=Box(-np.ones(size), np.ones(size), dtype=jnp.float32),
                    default_params=lambda: as_float32(BraxParams()), timestep=float(env.dt), name=name,
                    finite=is_finite)


def is_finite(physics) -> jax.Array:
    """bool: the pipeline state's generalized coordinates ``q`` and velocities ``qd`` are finite (every
    backend's state has them, and a NaN anywhere in a step reaches them; the arena checks the observation
    and reward itself), rather than a reduction over every array of Brax's state."""
    return faults.all_finite((physics.pipeline_state.q, physics.pipeline_state.qd))


def check_action_range(name: str, env) -> None:
    """Checks that ``env`` takes actions in [-1, 1] (rescaling env, or actuators of ``ctrlrange`` [-1, 1])."""
    if name in RESCALING_ENVS:
        return
    ctrl_range = np.asarray(env.sys.actuator.ctrl_range)
    if not np.allclose(ctrl_range, [-1.0, 1.0]):
        raise NotImplementedError(f"brax env {name!r} passes actions to actuators of ctrlrange "
                                  f"{ctrl_range.tolist()}, not [-1, 1]; its action spec is unknown to jarena")


def observe(physics, params) -> dict[str, jax.Array]:
    return {"state": jnp.asarray(physics.obs, jnp.float32)}


def sensor(name: str = "brax") -> Sensor:
    """Brax's observation vector as ``{"state": (obs_size,) float32}``."""
    return Sensor(observe=observe, name=name)


def brax_task() -> Task:
    """Brax's reward, termination (``done``) and metrics, read from the physics state after each step."""

    def reset(key, physics, outcome, params):
        return outcome.replace(metrics={**outcome.metrics, **physics.metrics}), ()

    def update(state, outcome, transition, params):
        physics = transition.physics
        return outcome.replace(reward=outcome.reward + physics.reward,
                               terminated=outcome.terminated | (physics.done > 0),
                               metrics={**outcome.metrics, **physics.metrics}), state

    return Task(update=update, reset=reset, name="brax")
