"""Cloth manipulation arenas in pure JAX: SoftGym's fabric flattening and folding with pick-and-place, from pixels.

Builder ``cloth``::

    cloth|domain:square_fabric,initial:crumpled,action:pixel_pick_and_place(1),task:flattening

- domains (:data:`DOMAINS`): ``square_fabric`` (0.4 x 0.4 m, SoftGym's mono-square-fabric) and
  ``rectangular_fabric`` (0.5 x 0.3 m); ``particles`` along the longer side (default 40), ``size`` to
  override the size in metres (``size:0.3`` or ``size:[0.5,0.3]``).
- ``initial``: ``crumpled`` or ``flat`` (:mod:`.initial`).
- ``action``: ``pixel_pick_and_place(K)``, ``pick_and_place(K)`` or the low-level ``picker(speed)``
  (:mod:`.tools`); the cloth gets the K pickers the tool moves.
- ``task``: ``flattening``, or a fold: ``side_fold``, ``diagonal_fold``, ``one_corner_inward`` (:mod:`.tasks`;
  a fold's goal particle positions are in ``info.goal``).
- ``horizon``: actions per episode (SoftGym's defaults: 30 for flattening, 15 for a fold from a flat start,
  45 from a crumpled one).
- observations (:mod:`.camera`): ``rgb`` uint8 (R, R, 3), ``depth`` float32 (R, R) metres and ``mask``
  uint8 (R, R) from the top-down camera, ``resolution`` R (default 128); ``depth:false`` and ``mask:false``
  drop those two (a pixel policy that reads only ``rgb``, and smaller datasets). Oracles read the particles
  from ``arena.privileged(state).physics.positions``.
- ``substeps``: XPBD substeps per 10 ms physics step (default 8; the constraint passes and collisions run once
  per substep: fewer leave the cloth stretchier and its layers less well kept apart, more make it stiffer). 8 is
  also the fastest for crumpled cloths on a GPU: with fewer, the softer piles crowd the neighbour search
  (``benchmarks/RESULTS.md``, "Cloth").
- ``solver``: how the physics substeps run (:data:`.physics.SOLVERS`): ``auto`` (default: the fused Pallas
  kernel of :mod:`.fused` on a GPU, jax.numpy elsewhere), ``xla`` or ``fused``.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.assemble import split_sizes
from jarena.arenas.cloth import camera as camera_lib
from jarena.arenas.cloth import tasks as tasks_lib
from jarena.arenas.cloth import tools as tools_lib
from jarena.arenas.cloth.initial import INITIAL_STATES
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.arenas.cloth.physics import SOLVERS, ClothPhysics
from jarena.building.builder import make_task, make_tool, register_arena_builder, register_tool
from jarena.building.grammar import ArenaStringError, Call
from jarena.building.registry import unknown_choice
from jarena.core.arena import Arena
from jarena.core.chain import chain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.resets import reset_strategy
from jarena.core.spec import Box, Dict, image_spec
from jarena.tasks.time_limit import time_limit

DOMAINS: dict[str, tuple[float, float]] = {"square_fabric": (0.4, 0.4), "rectangular_fabric": (0.5, 0.3)}
"""Domain -> default (width along x, height along y), metres."""
TASKS = {"flattening": lambda mesh, initial: tasks_lib.flattening(mesh),
         **{kind: (lambda mesh, initial, kind=kind: tasks_lib.folding(mesh, kind, canonical=initial != "flat"))
            for kind in tasks_lib.FOLDS}}
"""Task -> ``(mesh, initial) -> Task`` (a fold from a crumpled start aims at the canonical flat pose)."""
HORIZONS = {"flattening": 30, **{kind: 15 for kind in tasks_lib.FOLDS}}
"""Task -> default actions per episode from a flat start (SoftGym's); a fold from a crumpled start gets
``CRUMPLED_FOLD_EXTRA`` more, to flatten first."""
CRUMPLED_FOLD_EXTRA = 30
PICKER_TOOLS = ("pick_and_place", "pixel_pick_and_place")
DEFAULT_ACTION = Call("pixel_pick_and_place", (1,))

for _name, _factory in [("pick_and_place", tools_lib.pick_and_place),
                        ("pixel_pick_and_place", tools_lib.pixel_pick_and_place), ("picker", tools_lib.picker)]:
    register_tool(_name, _factory)


def _num_pickers(action: Any) -> int:
    """How many pickers the action tool moves (its first argument for the pick-and-place primitives)."""
    calls = [Call(c) if isinstance(c, str) else c for c in (action if isinstance(action, list) else [action])]
    for call in calls:
        if isinstance(call, Call) and call.name in PICKER_TOOLS:
            kwargs = dict(call.kwargs)
            value = call.args[0] if call.args else kwargs.get("num_pickers", 1)
            if not isinstance(value, int) or value < 1:
                raise ArenaStringError(f"{call.name} needs a positive number of pickers, got {value!r}")
            return value
    return 1


def _size(domain: str, size: Any) -> tuple[float, float]:
    if size is None:
        return DOMAINS[domain]
    values = size if isinstance(size, list) else [size, size]
    if len(values) != 2 or not all(isinstance(v, int | float) and 0.05 <= v <= 1.0 for v in values):
        raise ArenaStringError(f"size must be a side or [width, height] in metres within [0.05, 1.0], got {size!r}")
    return float(values[0]), float(values[1])


def camera_sensor(mesh: ClothMesh, resolution: int, depth: bool = True, mask: bool = True) -> Sensor:
    """The top-down camera: ``rgb``, and unless switched off ``depth`` and ``mask``, of ``resolution`` x
    ``resolution`` pixels."""
    r = int(resolution)
    height = float(camera_lib.CameraParams().height)
    spaces = {"rgb": image_spec(r, r), "depth": Box(0.0, height, (r, r), jnp.float32),
              "mask": Box(0, 1, (r, r), jnp.uint8)}
    keys = ("rgb",) + (("depth",) if depth else ()) + (("mask",) if mask else ())

    def observe(physics, params):
        image = camera_lib.render(physics.positions, mesh, params, r)
        image = {"rgb": image["rgb"], "depth": image["depth"], "mask": image["mask"].astype(jnp.uint8)}
        return {k: image[k] for k in keys}

    spec = Dict(**{k: spaces[k] for k in keys})
    return Sensor(observe=observe, spec=spec, name=f"top_down_camera({r}{'' if depth else ',no depth'}"
                                                   f"{'' if mask else ',no mask'})",
                  default_params=lambda: jax.tree_util.tree_map(jnp.float32, camera_lib.CameraParams()))


_render_jit = jax.jit(camera_lib.render, static_argnums=(1, 3))
"""The camera for host-side frames (videos), compiled once per mesh and frame size, not once per frame."""


def cloth_dynamics(physics: ClothPhysics, initial: str) -> Dynamics:
    """The cloth as a :class:`Dynamics`, its episodes starting from ``initial`` (a key of ``INITIAL_STATES``)."""
    make = INITIAL_STATES[initial]
    mesh = physics.mesh

    def render(state, params=None, *, width: int = 320, height: int = 240, **_):
        size = int(max(width, height))
        image = _render_jit(state.positions, mesh, camera_lib.CameraParams(), size)
        rgb = np.asarray(image["rgb"])
        top, left = (size - height) // 2, (size - width) // 2
        return rgb[top:top + height, left:left + width]

    return Dynamics(init=lambda key, params: make(key, physics, params), step=physics.step,
                    control_spec=physics.control_spec, default_params=physics.default_params, timestep=physics.dt,
                    render=render, name="cloth",
                    finite=lambda state: jnp.all(jnp.isfinite(state.positions) & jnp.isfinite(state.velocities)))


def build(domain: str = "square_fabric", task: str = "flattening", initial: str = "crumpled",
          action: Any = DEFAULT_ACTION, particles: int = 40, size: Any = None, resolution: int = 128,
          substeps: int = 8, horizon: int | None = None, wrap: Any = None, eval_episodes: int | None = None,
          val_episodes: int | None = None, auto_reset: str = "lazy", depth: bool = True,
          mask: bool = True, solver: str = "auto") -> Arena:
    """Builds a cloth arena (see the module docstring for the keys)."""
    if domain not in DOMAINS:
        raise ArenaStringError(unknown_choice("cloth domain", domain, list(DOMAINS)))
    if task not in TASKS:
        raise ArenaStringError(unknown_choice("cloth task", task, list(TASKS)))
    if initial not in INITIAL_STATES:
        raise ArenaStringError(unknown_choice("cloth initial state", initial, list(INITIAL_STATES)))
    for key, value, low in [("particles", particles, 3), ("resolution", resolution, 16), ("substeps", substeps, 1)]:
        if not isinstance(value, int) or value < low:
            raise ArenaStringError(f"{key} must be an integer >= {low}, got {value!r}")
    for key, value in [("depth", depth), ("mask", mask)]:
        if not isinstance(value, bool):
            raise ArenaStringError(f"{key} must be true or false, got {value!r}")
    if horizon is not None and (not isinstance(horizon, int) or horizon < 1):
        raise ArenaStringError(f"horizon must be a positive number of actions, got {horizon!r}")
    if solver != "auto" and solver not in SOLVERS:
        raise ArenaStringError(unknown_choice("cloth solver", solver, ["auto", *SOLVERS]))
    try:
        reset_strategy(auto_reset)
    except ValueError as e:
        raise ArenaStringError(str(e)) from None
    width, height = _size(domain, size)
    mesh = ClothMesh.of_size(width, height, cols=particles) if width >= height else \
        ClothMesh.of_size(width, height, particles_per_metre=(particles - 1) / height)
    physics = ClothPhysics(mesh, num_pickers=_num_pickers(action), substeps=substeps, solver=solver)
    tool = make_tool(action)
    steps = max(tool.substeps, 1)
    if horizon is None:
        horizon = HORIZONS[task] + (CRUMPLED_FOLD_EXTRA if task in tasks_lib.FOLDS and initial != "flat" else 0)
    tasks = [TASKS[task](mesh, initial), time_limit(horizon * steps)]
    if wrap is not None:
        tasks.append(make_task(wrap))
    extra = split_sizes(eval_episodes, val_episodes)
    arena = Arena(dynamics=cloth_dynamics(physics, initial), sensor=camera_sensor(mesh, resolution, depth, mask),
                  task=chain(*tasks), tool=tool, name=f"cloth-{domain}-{task}", auto_reset=auto_reset, **extra)
    try:
        _ = arena.action_spec
    except (TypeError, ValueError) as e:
        raise ArenaStringError(f"action tool {action} does not fit the cloth: {e}") from None
    return arena


def variants() -> list[tuple[str, tuple[str, ...]]]:
    out = []
    for domain in DOMAINS:
        for task in TASKS:
            for initial in INITIAL_STATES:
                # the benchmarks: flattening from crumpled starts, folding from flat ones (SoftGym's)
                benchmark = initial == ("crumpled" if task == "flattening" else "flat")
                tags = ("cloth", "pixels") + (("benchmark",) if benchmark else ())
                out.append((f"cloth|domain:{domain},initial:{initial},action:pixel_pick_and_place(1),task:{task}",
                            tags))
    return out


register_arena_builder("cloth", build, variants=variants, tags=("cloth",))
