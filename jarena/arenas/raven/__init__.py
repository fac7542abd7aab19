"""Ravens' tabletop rearrangement on MJX: a floating suction cup, pick-and-place actions in heightmap pixels.

Builder ``raven``::

    raven|task:block-insertion

- ``task``: a Ravens task (:data:`.tasks.TASKS`): ``block-insertion``, ``place-red-in-green``,
  ``align-box-corner``, ``stack-block-pyramid``, ``towers-of-hanoi``, ``palletizing-boxes``, ``packing-boxes``,
  ``assembling-kits`` (its eval and val episodes draw unseen shapes: :mod:`.splits`).
- observations (:mod:`.heightmap`): Ravens' top-down orthographic heightmap of the workspace (x in [0.25, 0.75] m,
  y in [-0.5, 0.5] m, 3.125 mm per pixel): ``rgb`` uint8 (320, 160, 3) and ``height`` float32 (320, 160) metres.
- actions (:mod:`.primitive`): float32 (5,) ``(pick_row, pick_col, place_row, place_col, place_yaw)``, one
  pick-and-place of Ravens' suction primitive; ``action`` puts more tools in front of it (``rescale(-1,1)``).
- physics (:mod:`.physics`): MJX, the cup moved kinematically, a weld equality switched per arena for suction;
  ``timestep`` (seconds, default 0.005), ``substeps`` physics steps per control step of the cup (4), ``settle``
  control steps after each place (8) and the constraint solver's ``iterations`` (10). Fewer iterations or
  coarser steps throw blocks dropped on the fixture's 2 mm walls (see ``docs/arenas/raven.md``).
- scoring (:mod:`.scoring`): Ravens' pose matching (or zone coverage) in stages with partial credit; an episode's
  rewards add up to at most 1, success when they pass 0.99; ``horizon`` actions per episode (Ravens' ``max_steps``
  by default).
- oracles read ``arena.privileged(state)``: the physics (``.physics``, :class:`.physics.RavenPhysics`, with its
  scene) and the goal (:func:`.scoring.goal_state` of ``.task``).
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.raven import heightmap, splits
from jarena.arenas.raven.physics import RavenPhysics, raven_dynamics
from jarena.arenas.raven.primitive import pick_and_place
from jarena.arenas.raven.scene import PhysicsOptions, Scene, build_scene
from jarena.arenas.raven.scoring import pose_goal
from jarena.arenas.raven.tasks import TASKS
from jarena.building.builder import make_task, make_tool, register_arena_builder
from jarena.building.grammar import ArenaStringError
from jarena.building.registry import unknown_choice
from jarena.core.arena import Arena
from jarena.core.chain import chain
from jarena.core.dynamics import Sensor
from jarena.core.resets import reset_strategy
from jarena.core.spec import Box, Dict, image_spec
from jarena.tasks.time_limit import time_limit

__all__ = ["TASKS", "build", "heightmap_sensor"]


def heightmap_sensor(scene: Scene) -> Sensor:
    """The top-down heightmap: ``rgb`` uint8 (320, 160, 3) and ``height`` float32 (320, 160), metres."""
    shape = (heightmap.ROWS, heightmap.COLS)
    spec = Dict(rgb=image_spec(*shape), height=Box(heightmap.BOUNDS[2][0], heightmap.BOUNDS[2][1], shape,
                                                   jnp.float32))

    def observe(physics: RavenPhysics, params):
        view = heightmap.render(scene, physics.data.geom_xpos, physics.data.geom_xmat, physics.geom_size,
                                physics.geom_rgb)
        return {"rgb": view.rgb, "height": view.height}

    return Sensor(observe=observe, spec=spec, name="heightmap(320x160)")


def _renderer(scene: Scene):
    """Host frames for videos: the heightmap's colours seen from above with +x up (y to the left), scaled by nearest
    pixels to fit the frame, centred on black."""
    draw = jax.jit(lambda xpos, xmat, size, colour: heightmap.render(scene, xpos, xmat, size, colour).rgb)

    def render(physics: RavenPhysics, params=None, *, width: int = 320, height: int = 240, **_):
        rgb = np.asarray(draw(physics.data.geom_xpos, physics.data.geom_xmat, physics.geom_size,
                              physics.geom_rgb)).transpose(1, 0, 2)[::-1, ::-1]
        scale = min(height / rgb.shape[0], width / rgb.shape[1])
        rows, cols = max(int(rgb.shape[0] * scale), 1), max(int(rgb.shape[1] * scale), 1)
        image = rgb[np.arange(rows) * rgb.shape[0] // rows][:, np.arange(cols) * rgb.shape[1] // cols]
        frame = np.zeros((height, width, 3), np.uint8)
        top, left = (height - rows) // 2, (width - cols) // 2
        frame[top:top + rows, left:left + cols] = image
        return frame

    return render


def _split_layout(initialize, held_out, key, physics):
    """A task's layout of the episode of ``key`` given whether it is held out (:attr:`.tasks.RavenTask.by_split`)."""
    return initialize(key, physics, held_out(key))


def _positive(key: str, value: Any, kind=int) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float if kind is float else int) or not value > 0:
        raise ArenaStringError(f"{key} must be a positive {'number' if kind is float else 'integer'}, got {value!r}")


def build(task: str = "block-insertion", timestep: float = 0.005, substeps: int = 4, settle: int = 8,
          iterations: int = 10, horizon: int | None = None, action: Any = None, wrap: Any = None,
          eval_episodes: int | None = None, val_episodes: int | None = None, auto_reset: str = "lazy") -> Arena:
    """Builds a Raven arena (see the module docstring for the keys)."""
    if task not in TASKS:
        raise ArenaStringError(unknown_choice("raven task", task, list(TASKS)))
    _positive("timestep", timestep, float)
    for key, value in [("substeps", substeps), ("settle", settle), ("iterations", iterations)] + (
            [("horizon", horizon)] if horizon is not None else []):
        _positive(key, value)
    try:
        reset_strategy(auto_reset)
    except ValueError as e:
        raise ArenaStringError(str(e)) from None
    spec = TASKS[task]()
    scene = build_scene(spec.items, PhysicsOptions(timestep=float(timestep), iterations=iterations,
                                                   ls_iterations=iterations, max_geom_pairs=spec.max_geom_pairs),
                        spec.pairs)
    dynamics = raven_dynamics(scene, substeps, render=_renderer(scene))
    primitive = pick_and_place(settle, spec.after_action)
    tool = chain(make_tool(action), primitive) if action is not None else primitive
    initialize = spec.initialize
    if spec.by_split:
        held_out = splits.held_out(Arena.num_eval_episodes if eval_episodes is None else int(eval_episodes),
                                   Arena.num_val_episodes if val_episodes is None else int(val_episodes))
        initialize = functools.partial(_split_layout, spec.initialize, held_out)
    tasks = [pose_goal(spec.goal, spec.name, spec.pos_eps, initialize),
             time_limit((horizon or spec.max_steps) * tool.substeps)]
    if wrap is not None:
        tasks.append(make_task(wrap))
    extra = {}
    if eval_episodes is not None:
        extra["num_eval_episodes"] = int(eval_episodes)
    if val_episodes is not None:
        extra["num_val_episodes"] = int(val_episodes)
    arena = Arena(dynamics=dynamics, sensor=heightmap_sensor(scene), task=chain(*tasks), tool=tool,
                  name=f"raven-{task}", auto_reset=auto_reset, **extra)
    try:
        _ = arena.action_spec
    except (TypeError, ValueError) as e:
        raise ArenaStringError(f"action tools {action} do not fit the pick-and-place primitive: {e}") from None
    return arena


def variants() -> list[tuple[str, tuple[str, ...]]]:
    return [(f"raven|task:{name}", ("raven", "pixels", "benchmark")) for name in TASKS]


register_arena_builder("raven", build, variants=variants, tags=("raven",))
