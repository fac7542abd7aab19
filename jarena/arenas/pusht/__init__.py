"""PushT in pure JAX: Diffusion Policy's planar pushing task (``pusht_env``), batched on the device.

A kinematic disc, driven by a PD law towards the agent's target point, pushes a T-shaped block across a
512 x 512 plane inside four walls until it covers a fixed goal T. Builder ``pusht``::

    pusht|obs:image
    pusht|obs:state,time_limit:300,action:noise(5.0)

- ``obs``: ``image`` (``image``, uint8 (R, R, 3), the top-down view with the goal drawn, and ``agent_pos``,
  float32 (2,)), ``state`` (``state``, float32 (5,): pusher x, y, block x, y and angle wrapped to [0, 2 pi), as
  ``pusht_env``) or ``keypoints`` (``keypoints``, float32 (9, 2), points of the T in the plane, and
  ``agent_pos``: ``pusht_env``'s keypoint variant, the one Diffusion Policy's state results use).
- ``resolution``: the image's side R in pixels (96). Images are drawn on the device (:mod:`.render`).
- action: the pusher's target point, float32 (2,) in ``[0, 512]^2`` (outside values are clipped); one action
  holds for ``substeps`` physics steps of 10 ms (10: control at 10 Hz); ``action:`` adds tools in front.
- ``time_limit``: actions per episode (300); ``iterations``: passes of the contact solver per physics step (10,
  pymunk's default).
- task (:mod:`.task`): reward ``clip(coverage / 0.95, 0, 1)``, success and termination at coverage > 0.95; the
  metrics ``coverage``, ``max_coverage`` and ``max_reward`` (Diffusion Policy's score, at an episode's last
  step). Physics in :mod:`.physics`, exact coverage in :mod:`.overlap`.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.assemble import split_sizes
from jarena.arenas.pusht import geometry
from jarena.arenas.pusht import physics as physics_lib
from jarena.arenas.pusht import render as render_lib
from jarena.arenas.pusht.geometry import GOAL_POSE, KEYPOINTS
from jarena.arenas.pusht.overlap import coverage
from jarena.arenas.pusht.physics import PushTParams, PushTState, block_pose
from jarena.arenas.pusht.task import PushTaskParams, push_t
from jarena.building.builder import make_task, make_tool, register_arena_builder
from jarena.building.grammar import ArenaStringError
from jarena.building.registry import unknown_choice
from jarena.core.arena import Arena
from jarena.core.chain import chain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.resets import reset_strategy
from jarena.core.spec import Box, Dict, image_spec
from jarena.core.tree import as_float32
from jarena.tasks.time_limit import time_limit as time_limit_task

__all__ = ["GOAL_POSE", "KEYPOINTS", "OBSERVATIONS", "PushTParams", "PushTState", "PushTaskParams", "block_pose",
           "build", "coverage", "dynamics", "push_t", "sensor"]

OBSERVATIONS = ("image", "state", "keypoints")
TIME_LIMIT = 300
REACH = 256.0
"""How far past the plane's edges the block's points can be observed: a block squeezed between the pusher (whose
centre stays in the plane) and a wall is pushed into the wall, by at most the pusher's radius and the T's span."""

_render_jit = jax.jit(render_lib.render, static_argnames=("size", "samples"))
"""The renderer, compiled once per image size for host-side frames (videos) and eager steps (inlined where the
caller jits)."""
_init_jit = jax.jit(physics_lib.init)
_step_jit = jax.jit(physics_lib.step, static_argnames=("substeps", "iterations"))
"""A reset's draw and one action's physics as one program each: inlined where the caller jits, compiled once (not
op by op, a step's loops anew on every call) where they run eagerly."""


def dynamics(substeps: int = 10, iterations: int = 10) -> Dynamics:
    """The scene as a :class:`Dynamics` whose step is one action: ``substeps`` physics steps towards the target.

    Control: float32 (2,), the pusher's target point in ``[0, 512]^2``; its no-op is the plane's centre (a target
    point always moves the pusher: there is no action that leaves it be).
    """
    substeps, iterations = int(substeps), int(iterations)

    def render(state, params=None, *, width: int = 320, height: int = 240, **_):
        size = int(min(width, height))
        image = np.asarray(_render_jit(state.pusher, block_pose(state), size=size, samples=2))
        frame = np.full((int(height), int(width), 3), 255, np.uint8)
        top, left = (int(height) - size) // 2, (int(width) - size) // 2
        frame[top:top + size, left:left + size] = image
        return frame

    def step(state, target, params):
        return _step_jit(state, target, params, substeps=substeps, iterations=iterations)

    return Dynamics(init=_init_jit, step=step,
                    control_spec=Box(0.0, geometry.SIZE, (2,), jnp.float32),
                    default_params=lambda: as_float32(PushTParams()),
                    no_op=lambda: jnp.full((2,), geometry.SIZE / 2, jnp.float32),
                    timestep=float(PushTParams().dt) * substeps, render=render, name="pusht")


def _agent_pos(physics: PushTState) -> jax.Array:
    # the pusher tracks targets in the plane without overshoot; the clip only removes float rounding
    return jnp.clip(physics.pusher, 0.0, geometry.SIZE)


def sensor(obs: str = "image", resolution: int = 96) -> Sensor:
    """What the agent sees: ``obs`` in :data:`OBSERVATIONS` (see the module docstring)."""
    plane = Box(0.0, geometry.SIZE, (2,), jnp.float32)
    if obs == "image":
        r = int(resolution)

        def observe(physics, params):
            image = _render_jit(physics.pusher, block_pose(physics), size=r, samples=2)
            return {"image": image, "agent_pos": _agent_pos(physics)}

        return Sensor(observe=observe, spec=Dict(image=image_spec(r, r), agent_pos=plane), name=f"pusht_image({r})")
    if obs == "state":
        low = np.array([0.0, 0.0, -REACH, -REACH, 0.0], np.float32)
        high = np.array([geometry.SIZE, geometry.SIZE, geometry.SIZE + REACH, geometry.SIZE + REACH, 2 * math.pi],
                        np.float32)

        def observe(physics, params):
            angle = jnp.mod(physics.block_angle, 2 * jnp.pi)
            return {"state": jnp.concatenate([_agent_pos(physics), physics.block, angle[None]]).astype(jnp.float32)}

        return Sensor(observe=observe, spec=Dict(state=Box(low, high, (5,), jnp.float32)), name="pusht_state")
    if obs == "keypoints":
        def observe(physics, params):
            return {"keypoints": geometry.keypoints(block_pose(physics)), "agent_pos": _agent_pos(physics)}

        points = Box(-REACH, geometry.SIZE + REACH, (len(KEYPOINTS), 2), jnp.float32)
        return Sensor(observe=observe, spec=Dict(keypoints=points, agent_pos=plane), name="pusht_keypoints")
    raise ValueError(unknown_choice("pusht observation", obs, list(OBSERVATIONS)))


def build(obs: str = "image", resolution: int = 96, time_limit: int = TIME_LIMIT, substeps: int = 10,
          iterations: int = 10, action: Any = None, wrap: Any = None, eval_episodes: int | None = None,
          val_episodes: int | None = None, auto_reset: str = "select") -> Arena:
    """Builds a PushT arena (see the module docstring for the keys)."""
    if obs not in OBSERVATIONS:
        raise ArenaStringError(unknown_choice("pusht observation", obs, list(OBSERVATIONS)))
    for key, value, low in [("resolution", resolution, 8), ("time_limit", time_limit, 1), ("substeps", substeps, 1),
                            ("iterations", iterations, 1)]:
        if not isinstance(value, int) or isinstance(value, bool) or value < low:
            raise ArenaStringError(f"pusht {key} must be an integer >= {low}, got {value!r}")
    try:
        reset_strategy(auto_reset)
    except ValueError as e:
        raise ArenaStringError(str(e)) from None
    tasks = [push_t(), time_limit_task(time_limit)]
    if wrap is not None:
        tasks.append(make_task(wrap))
    extra = split_sizes(eval_episodes, val_episodes)
    arena = Arena(dynamics=dynamics(substeps, iterations), sensor=sensor(obs, resolution), task=chain(*tasks),
                  tool=make_tool(action) if action is not None else Arena.tool, name=f"pusht-{obs}",
                  auto_reset=auto_reset, **extra)
    try:
        _ = arena.action_spec
    except (TypeError, ValueError) as e:
        raise ArenaStringError(f"action tools {action} do not fit pusht's control (a target point, "
                               f"{arena.dynamics.control_spec!r}): {e}") from None
    return arena


def variants() -> list[tuple[str, tuple[str, ...]]]:
    return [("pusht|obs:image", ("pusht", "pixels", "benchmark")), ("pusht|obs:state", ("pusht",)),
            ("pusht|obs:keypoints", ("pusht", "benchmark"))]


register_arena_builder("pusht", build, variants=variants, tags=("pusht",))
