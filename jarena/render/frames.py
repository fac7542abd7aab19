"""Frames of selected arenas of a batch: pull only their physics to the host and render them there.

Rendering is host-side work (``Dynamics.render``: MuJoCo's renderer, numpy drawings), done after a
compiled rollout has collected the physics states on device, never per step inside it. Only the
selected arenas (and time steps) are gathered on device and copied with ``jax.device_get``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Any

import jax
import numpy as np

from jarena.core.arena import Arena
from jarena.core.types import ArenaParams, ArenaState

PyTree = Any


class RenderError(ValueError):
    """An arena that cannot render, or bad rendering arguments."""


def can_render(arena: Arena) -> bool:
    """Whether ``arena``'s dynamics have a ``render`` function."""
    return arena.dynamics.render is not None


@functools.cache
def rendering_arenas() -> tuple[str, ...]:
    """``builder|domain:name`` of every listed arena family whose dynamics render (builds one arena of each)."""
    from jarena.building import build_arena, list_arenas, parse_arena_string

    families: dict[str, bool] = {}
    for string in list_arenas():
        parsed = parse_arena_string(string)
        family = f"{parsed.builder}|domain:{parsed.pairs['domain']}" if "domain" in parsed.pairs else parsed.builder
        if family in families:
            continue
        try:
            families[family] = can_render(build_arena(string))
        except Exception:  # an optional dependency missing: that family cannot render here
            families[family] = False
    return tuple(f for f, ok in families.items() if ok)


def renderer(arena: Arena) -> Callable[..., np.ndarray]:
    """``arena.dynamics.render``, or a :class:`RenderError` naming the arena and those that render."""
    if arena.dynamics.render is None:
        raise RenderError(f"arena {arena.build_string or arena.name!r} cannot render: its dynamics "
                          f"{arena.dynamics.name!r} have no render function (Dynamics.render). Arenas that render: "
                          f"{', '.join(rendering_arenas())}")
    return arena.dynamics.render


def _physics(states: ArenaState | PyTree) -> PyTree:
    return states.physics if isinstance(states, ArenaState) else states


def _batch_size(tree: PyTree, axis: int) -> int:
    leaves = jax.tree_util.tree_leaves(tree)
    if not leaves or np.ndim(leaves[0]) <= axis:
        raise RenderError(f"expected physics states with a batch axis {axis}, got leaves of shapes "
                          f"{[np.shape(x) for x in leaves[:3]]}")
    return int(np.shape(leaves[0])[axis])


def _indices(indices: int | Sequence[int] | None, size: int) -> np.ndarray:
    idx = np.arange(size) if indices is None else np.atleast_1d(np.asarray(indices, np.int64)).reshape(-1)
    if idx.size == 0:
        raise RenderError("no arenas selected to render")
    bad = idx[(idx < 0) | (idx >= size)]
    if bad.size:
        raise RenderError(f"arena indices {bad.tolist()} are out of range for a batch of {size} arenas")
    return idx


def _take(tree: PyTree, idx, time_major: bool, stride: int) -> PyTree:
    """Arenas ``idx`` of a batch (B, ...), or of a trajectory (T, B, ...) every ``stride``-th step."""
    if time_major:
        return jax.tree_util.tree_map(lambda x: x[::stride][:, idx], tree)
    return jax.tree_util.tree_map(lambda x: x[idx], tree)


_take_on_device = jax.jit(_take, static_argnums=(2, 3))  # one gather program for the whole tree


def _to_host(tree: PyTree, idx: np.ndarray, time_major: bool, stride: int = 1, stop: int | None = None) -> PyTree:
    """The selected arenas, gathered where the states live and then copied to the host; for trajectories,
    states ``[:stop:stride]`` (the cut happens on the host: one compiled gather serves all lengths)."""
    if any(isinstance(x, jax.Array) for x in jax.tree_util.tree_leaves(tree)):
        host = jax.device_get(_take_on_device(tree, idx, time_major, stride))
    else:
        host = _take(tree, idx, time_major, stride)
    if time_major and stop is not None:
        host = jax.tree_util.tree_map(lambda x: x[: -(-stop // stride)], host)
    return host


def _host_params(arena: Arena, params: ArenaParams | None, params_axis: int | None, idx: np.ndarray) -> list:
    """The dynamics params of each selected arena, on the host."""
    dynamics = (arena.default_params() if params is None else params).dynamics
    if params_axis is None:
        return [jax.device_get(dynamics)] * idx.size
    if params_axis != 0:
        raise RenderError(f"params_axis must be None (shared params) or 0 (per arena), got {params_axis!r}")
    picked = jax.device_get(jax.tree_util.tree_map(lambda x: x[idx], dynamics))
    return [jax.tree_util.tree_map(lambda x, i=i: x[i], picked) for i in range(idx.size)]


def render_batch(arena: Arena, states: ArenaState | PyTree, indices: int | Sequence[int] | None = None, *,
                 params: ArenaParams | None = None, params_axis: int | None = None, width: int = 320,
                 height: int = 240, camera: int | str = -1) -> np.ndarray:
    """Renders arenas ``indices`` (default: all) of a batch of states (leading axis B).

    Args:
      arena: the arena the states belong to.
      states: an :class:`ArenaState` (or its ``physics``) batched over B.
      indices: which arenas, an int or a sequence of ints.
      params: the batch's arena params, shared or per arena (see ``params_axis``).
      params_axis: ``None`` (params shared) or ``0`` (one per arena).
      width: image width in pixels, passed to ``Dynamics.render``.
      height: image height in pixels, passed to ``Dynamics.render``.
      camera: the camera, passed to ``Dynamics.render``.

    Returns:
      uint8 (K, height, width, 3) for the K selected arenas.
    """
    render = renderer(arena)
    physics = _physics(states)
    idx = _indices(indices, _batch_size(physics, 0))
    host = _to_host(physics, idx, time_major=False)
    dyn_params = _host_params(arena, params, params_axis, idx)
    return np.stack([render(jax.tree_util.tree_map(lambda x, k=k: x[k], host), dyn_params[k], width=width,
                            height=height, camera=camera) for k in range(idx.size)])


def render_trajectory(arena: Arena, states: ArenaState | PyTree, arenas: int | Sequence[int] = 0, *,
                      params: ArenaParams | None = None, params_axis: int | None = None, width: int = 320,
                      height: int = 240, camera: int | str = -1, stride: int = 1, num_states: int | None = None,
                      columns: int | None = None) -> np.ndarray:
    """Renders a trajectory of batched states, (T, B, ...), for the chosen arenas.

    Several arenas are tiled into a grid per frame (see :func:`tile`). Only the selected arenas, of the
    first ``num_states`` (default: all T) states every ``stride``-th, are copied to the host.

    Returns:
      uint8 (ceil(num_states / stride), H, W, 3): ``H, W = height, width`` for one arena, the grid's size
      otherwise.
    """
    if int(stride) < 1:
        raise RenderError(f"stride must be a positive integer, got {stride!r}")
    if num_states is not None and int(num_states) < 1:
        raise RenderError(f"num_states must be a positive integer, got {num_states!r}")
    render = renderer(arena)
    physics = _physics(states)
    idx = _indices(arenas, _batch_size(physics, 1))
    host = _to_host(physics, idx, True, int(stride), None if num_states is None else int(num_states))
    dyn_params = _host_params(arena, params, params_axis, idx)
    num_steps = _batch_size(host, 0)
    frames = np.stack([
        np.stack([render(jax.tree_util.tree_map(lambda x, t=t, k=k: x[t, k], host), dyn_params[k], width=width,
                         height=height, camera=camera) for t in range(num_steps)])
        for k in range(idx.size)])
    return frames[0] if idx.size == 1 else tile(frames, columns)


def tile(frames: np.ndarray, columns: int | None = None, border: int = 2) -> np.ndarray:
    """Tiles K videos (K, T, H, W, 3) into one (T, rows H + (rows - 1) border, ...) grid video.

    ``columns`` defaults to ``ceil(sqrt(K))``; empty cells and the ``border`` pixels between cells are black.
    """
    frames = np.asarray(frames)
    if frames.ndim != 5:
        raise RenderError(f"tile expects frames of shape (K, T, H, W, 3), got {frames.shape}")
    k, t, h, w, c = frames.shape
    columns = math.ceil(math.sqrt(k)) if columns is None else int(columns)
    if columns < 1:
        raise RenderError(f"columns must be a positive integer, got {columns}")
    columns = min(columns, k)
    rows = math.ceil(k / columns)
    out = np.zeros((t, rows * h + (rows - 1) * border, columns * w + (columns - 1) * border, c), frames.dtype)
    for i in range(k):
        r, col = divmod(i, columns)
        out[:, r * (h + border): r * (h + border) + h, col * (w + border): col * (w + border) + w] = frames[i]
    return out
