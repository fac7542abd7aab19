"""The DeepMind Control Suite on MJX, with each domain's dynamics shared by its tasks.

Builder ``dmc``: ``dmc|domain:<domain>,task:<task>[,action:<tools>][,time_limit:N][,wrap:<tasks>]
[,auto_reset:select|lazy|repeat][,<simulation options>][,pixels:N[,depth:true][,segmentation:true]
[,state:false][,camera:<name or id>][,frame_stack:K]]``.
Observations, rewards, initial states and episode lengths follow ``dm_control.suite``; tests compare
them with dm_control's own task code on the same physics states.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Iterator, Mapping
from typing import Any

from jarena.arenas.assemble import assemble
from jarena.arenas.domain import Domain
from jarena.building.builder import register_arena_builder
from jarena.building.grammar import ArenaStringError
from jarena.core.arena import Arena

#: Domains and their tasks. Static, so that listing arenas does not import MuJoCo; each domain's
#: module (``jarena.arenas.dmc.<domain>``) is imported when one of its arenas is built.
SUITE: dict[str, tuple[str, ...]] = {
    "cartpole": ("balance", "balance_sparse", "swingup", "swingup_sparse"),
    "cheetah": ("run",),
    "walker": ("stand", "walk", "run"),
    "hopper": ("stand", "hop"),
    "humanoid": ("stand", "walk", "run"),
    "swimmer": ("swimmer6",),
    "fish": ("upright", "swim"),
    "pendulum": ("swingup",),
    "acrobot": ("swingup", "swingup_sparse"),
    "point_mass": ("easy",),
    "reacher": ("easy", "hard"),
    "finger": ("spin", "turn_easy", "turn_hard"),
    "ball_in_cup": ("catch",),
}

#: Domains of the suite that MJX cannot simulate, and why (building them is a clear error).
UNSUPPORTED: dict[str, str] = {}


class _Domains(Mapping):
    """``SUITE``'s domains, each imported on first use."""

    def __getitem__(self, name: str) -> Domain:
        if name not in SUITE:
            raise KeyError(name)
        return importlib.import_module(f"jarena.arenas.dmc.{name}").DOMAIN

    def __iter__(self) -> Iterator[str]:
        return iter(SUITE)

    def __len__(self) -> int:
        return len(SUITE)


DOMAINS: Mapping[str, Domain] = _Domains()


def build(domain: str, task: Any = None, action: Any = None, time_limit: int | None = None, wrap: Any = None,
          eval_episodes: int | None = None, val_episodes: int | None = None, iterations: int | None = None,
          ls_iterations: int | None = None, integrator: str | None = None, eulerdamp: bool | None = None,
          timestep: float | None = None, max_contact_points: int | None = None, max_geom_pairs: int | None = None,
          touch_sensors: bool | None = None, auto_reset: str | None = None, pixels: Any = None,
          depth: bool | None = None, segmentation: bool | None = None, state: bool | None = None,
          camera: Any = None, frame_stack: int | None = None, differentiable: bool | None = None) -> Arena:
    """Builds a DeepMind Control Suite arena on MJX.

    Args:
      domain: one of ``DOMAINS`` (cartpole, walker, ...).
      task: a task of the domain (default: its first), e.g. ``walk``.
      action: action tools in front of the actuators, e.g. ``repeat(2)``.
      time_limit: episode length in control steps (default: the suite's, 1000 for most tasks).
      wrap: task transforms after the time limit, e.g. ``reward_scale(0.1)``.
      eval_episodes: size of the evaluation split.
      val_episodes: size of the validation split.
      iterations: MuJoCo solver iterations. This and the next six simulation options default to the suite
        model's; fewer solver iterations, ``integrator:euler``, ``eulerdamp:false``, a longer physics
        ``timestep`` and MJX contact culling are faster on MJX and less exact, as mujoco_playground's models
        (see ``common.with_options``).
      ls_iterations: MuJoCo line-search iterations.
      integrator: ``euler``, ``rk4`` or ``implicitfast``.
      eulerdamp: implicit joint damping in Euler steps (``false``: none).
      timestep: physics timestep (s); it must divide the control timestep.
      max_contact_points: MJX contact culling: contacts kept per collision function.
      max_geom_pairs: MJX contact culling: geom pairs kept per pair type.
      touch_sensors: ``false`` leaves the model's touch sensors out of the simulation, for domains whose
        tasks never read them (humanoid; Playground's humanoid has none).
      auto_reset: how finished episodes restart under auto-reset: ``select``, ``lazy`` or ``repeat``
        (each arena replays its first initial state, as Brax and Playground; fastest); default: the
        domain's (see ``jarena.core.resets``).
      pixels: camera images rendered on device (:mod:`jarena.arenas.mjx.camera`): ``pixels:64`` (or
        ``[height,width]``) adds ``observation["pixels"]`` uint8 (64, 64, 3) from camera 0, the camera
        dm_control's pixel wrapper uses.
      depth: with ``pixels``, also observe ``depth`` (float32 (H, W), metres along the camera axis).
      segmentation: with ``pixels``, also observe ``segmentation`` (int32 (H, W, 2): object id and ``mjtObj``
        type per pixel).
      state: with ``pixels``, ``false`` drops the state observation (images only); default ``true``.
      camera: with ``pixels``, the model camera's name or id (default 0).
      frame_stack: with ``pixels``, the last K images (and depth maps) instead of the last one:
        ``pixels`` (H, W, 3 K), oldest first (:func:`jarena.sensors.frame_stack`).
      differentiable: ``true`` keeps MJX's constraint line search as a fixed-length scan, so that reverse-mode
        gradients flow through ``step`` (default: a while loop, which gives the same states sooner;
        :mod:`jarena.arenas.mjx.dynamics`).
    """
    if domain in UNSUPPORTED:
        raise NotImplementedError(f"dmc domain {domain!r} cannot run on MJX: {UNSUPPORTED[domain]}")
    domains = DOMAINS
    options = (iterations, ls_iterations, integrator, eulerdamp, timestep, max_contact_points, max_geom_pairs,
               touch_sensors, differentiable)
    if any(o is not None for o in options) and domain in SUITE:
        from jarena.arenas.dmc import common
        dom = DOMAINS[domain]
        if touch_sensors is False and "touch" not in dom.unread_sensors:
            raise ValueError(f"touch_sensors:false: dmc domain {domain!r} has no unread touch sensors (its "
                             "tasks read them, or its model has none); domains that can leave them out: "
                             f"{', '.join(d for d in SUITE if 'touch' in DOMAINS[d].unread_sensors)}")
        optioned = {name: common.with_options(dom.dynamics_for(name), *options) for name in dom.tasks}
        domains = {domain: dataclasses.replace(dom, task_dynamics={n: (lambda d=d: d) for n, d in optioned.items()})}
    size = None
    if pixels is not None:
        from jarena.arenas.mjx.pixels import image_size
        try:
            size = image_size(pixels)
        except ValueError as e:
            raise ArenaStringError(str(e)) from None
    arena = assemble("dmc", domains, domain, task, action, time_limit, wrap, eval_episodes, val_episodes,
                     auto_reset=auto_reset,
                     sensor=_camera_options(size, depth, segmentation, state, camera, frame_stack))
    if size is not None:
        # a pixel arena is its own benchmark: its name (run directories, tuned configs) says so
        height, width = size
        label = str(height) if height == width else f"{height}x{width}"
        arena = dataclasses.replace(arena, name=f"{arena.name}-pixels{label}")
    return arena


def _camera_options(size, depth, segmentation, state, camera, frames):
    """A sensor transform adding camera images of ``size`` (height, width), or ``None`` without it (then the
    other options are errors)."""
    if size is None:
        given = [n for n, v in (("depth", depth), ("segmentation", segmentation), ("state", state),
                                ("camera", camera), ("frame_stack", frames)) if v is not None]
        if given:
            raise ArenaStringError(f"{', '.join(given)} need pixels (e.g. pixels:64)")
        return None
    for name, value in (("depth", depth), ("segmentation", segmentation), ("state", state)):
        if value is not None and not isinstance(value, bool):
            raise ArenaStringError(f"{name} must be true or false, got {value!r}")
    from jarena.arenas.mjx.dynamics import model_of
    from jarena.arenas.mjx.pixels import pixel_sensor
    from jarena.sensors import frame_stack

    def add_camera(sensor, dynamics):
        try:
            sensor = pixel_sensor(model_of(dynamics), sensor if state is not False else None, size,
                                  0 if camera is None else camera, depth=bool(depth), segmentation=bool(segmentation))
            if frames is not None:
                sensor = frame_stack(sensor, frames, ("pixels", "depth") if depth else ("pixels",))
            return sensor
        except ValueError as e:
            raise ArenaStringError(str(e)) from None

    return add_camera


def variants() -> list[tuple[str, tuple[str, ...]]]:
    """Every domain x task of the suite, tagged ``dmc``, ``mujoco`` and ``benchmark``."""
    return [(f"dmc|domain:{d},task:{t}", ("dmc", "mujoco", "benchmark")) for d, tasks in SUITE.items() for t in tasks]


register_arena_builder("dmc", build, variants=variants, tags=("dmc", "mujoco"))
