"""``frame_stack(sensor, k)``: the agent sees the last ``k`` observations of some keys instead of the last one.

Images ``(H, W, C)`` stack along their channels into ``(H, W, C k)``, oldest first, as dm_control's and DrQ's
pixel stacks; other arrays gain a trailing axis of ``k``, oldest first (``depth`` (H, W) -> (H, W, k)). At reset
the first observation fills all ``k`` slots (DrQ-v2's convention), so shapes never change within or across
episodes. The frames are the sensor's memory (``ArenaState.sensor``), so ``jit``, ``vmap``, auto-reset and
planners that copy states see them as any other state.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from jarena.core.dynamics import Sensor, SensorMemory
from jarena.core.spec import Box, Dict, Spec


def _is_image(shape: tuple[int, ...]) -> bool:
    return len(shape) == 3


def _stack(frames: jnp.ndarray, image: bool) -> jnp.ndarray:
    """``frames`` (k, ...) as one observation: channels concatenated for images, else a trailing axis."""
    if image:
        k, h, w, c = frames.shape
        return jnp.moveaxis(frames, 0, 2).reshape(h, w, k * c)
    return jnp.moveaxis(frames, 0, -1)


def _stacked_spec(spec: Box, k: int) -> Box:
    if _is_image(spec.shape):
        h, w, c = spec.shape
        tile = lambda a: np.concatenate([np.broadcast_to(a, spec.shape)] * k, axis=-1)  # noqa: E731
        return Box(tile(spec.low), tile(spec.high), (h, w, c * k), spec.dtype)
    tile = lambda a: np.stack([np.broadcast_to(a, spec.shape)] * k, axis=-1)  # noqa: E731
    return Box(tile(spec.low), tile(spec.high), spec.shape + (k,), spec.dtype)


def frame_stack(sensor: Sensor, k: int, keys: Sequence[str] = ("pixels",)) -> Sensor:
    """``sensor`` whose observation keys ``keys`` hold the last ``k`` observations (see the module docstring).

    Keys not in ``keys`` pass through. ``k = 1`` returns ``sensor`` unchanged. ``sensor`` may have a memory of
    its own, which runs first. Raises ``ValueError`` for ``k < 1``, and for ``keys`` the sensor's spec lacks.
    """
    if not isinstance(k, int) or isinstance(k, bool) or k < 1:
        raise ValueError(f"frame_stack needs a positive number of frames, got {k!r}")
    keys = tuple(keys)
    if not keys:
        raise ValueError("frame_stack needs at least one observation key to stack")
    if k == 1:
        return sensor
    spec: Spec | None = sensor.spec
    if spec is not None:
        missing = [key for key in keys if key not in spec.spaces]
        if missing:
            raise ValueError(f"frame_stack: sensor {sensor.name!r} observes no {missing}; its keys: "
                             f"{', '.join(spec.spaces)}")
        spec = Dict({name: _stacked_spec(s, k) if name in keys else s for name, s in spec.spaces.items()})
    inner = sensor.memory

    def check(observation):
        missing = [key for key in keys if key not in observation]
        if missing:
            raise ValueError(f"frame_stack: sensor {sensor.name!r} observes no {missing}; its keys: "
                             f"{', '.join(observation)}")

    def show(frames, observation):
        out = dict(observation)
        for key in keys:
            out[key] = _stack(frames[key], _is_image(observation[key].shape))
        return out

    def start(observation):
        inner_memory, observation = inner.start(observation) if inner is not None else ((), observation)
        check(observation)
        frames = {key: jnp.stack([observation[key]] * k) for key in keys}
        return (inner_memory, frames), show(frames, observation)

    def advance(memory, observation):
        inner_memory, frames = memory
        if inner is not None:
            inner_memory, observation = inner.advance(inner_memory, observation)
        frames = {key: jnp.concatenate([frames[key][1:], observation[key][None]]) for key in keys}
        return (inner_memory, frames), show(frames, observation)

    return dataclasses.replace(sensor, spec=spec, name=f"frame_stack({sensor.name}, {k})",
                               memory=SensorMemory(start=start, advance=advance))
