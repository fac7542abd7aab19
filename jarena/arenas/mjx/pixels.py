"""Camera observations for MJX arenas: a sensor that adds images rendered on device to (or in place of) the
state observation.

``pixel_sensor(model, base, size=64)`` observes ``{**base, "pixels": uint8 (H, W, 3)}``, optionally with
``"depth"`` (float32 (H, W), metres along the camera axis) and ``"segmentation"`` (int32 (H, W, 2), object id and
``mjtObj`` type), rendered by :mod:`jarena.arenas.mjx.camera` from the physics state the arena observes (after
each step, kinematics are current). A pure function of the state: ``jit``, ``vmap`` and ``lax.scan`` apply
as to any sensor.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
from mujoco import mjx

from jarena.arenas.mjx import camera as camera_lib
from jarena.core.dynamics import Sensor
from jarena.core.spec import Box, Dict, image_spec, spec_from_value

#: Observation keys the pixel sensor writes (a state sensor may not use them).
IMAGE_KEYS = ("pixels", "depth", "segmentation")


def image_size(size) -> tuple[int, int]:
    """``(height, width)`` from an int (square) or a pair; a ``ValueError`` naming the value otherwise."""
    values = list(size) if isinstance(size, list | tuple) else [size, size]
    if len(values) != 2 or not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 4096
                                   for v in values):
        raise ValueError(f"pixels must be a side or [height, width] in pixels within [1, 4096], got {size!r}")
    return int(values[0]), int(values[1])


def pixel_sensor(model: mujoco.MjModel, base: Sensor | None = None, size=64, camera: int | str = 0,
                 depth: bool = False, segmentation: bool = False) -> Sensor:
    """A sensor of ``base``'s observation (none if ``None``) plus images from ``camera`` of ``model``.

    Args:
      model: the MuJoCo model the arena's ``mjx.Data`` belongs to.
      base: the state sensor whose keys are kept, or ``None`` for images only.
      size: image side, or ``(height, width)``, in pixels.
      camera: a model camera's name or id (dm_control's pixel wrapper uses camera 0).
      depth: also observe ``depth``.
      segmentation: also observe ``segmentation``.
    """
    height, width = image_size(size)
    scene = camera_lib.scene_of(model)
    camera_id = scene.camera(camera)

    base_spec = None
    if base is not None:
        shapes = jax.eval_shape(lambda: base.observe(mjx.make_data(model), base.default_params()))
        clash = sorted(set(shapes) & set(IMAGE_KEYS))
        if clash:
            raise ValueError(f"the state sensor {base.name!r} already observes {clash}")
        base_spec = base.spec if base.spec is not None else spec_from_value(shapes)

    def observe(data, params):
        observation = dict(base.observe(data, params)) if base is not None else {}
        frame = camera_lib.render(scene, data, camera_id, height, width)
        observation["pixels"] = frame.rgb
        if depth:
            observation["depth"] = frame.depth
        if segmentation:
            observation["segmentation"] = frame.segmentation
        return observation

    spaces = dict(base_spec.spaces) if base_spec is not None else {}
    spaces["pixels"] = image_spec(height, width)
    if depth:
        spaces["depth"] = Box(0.0, scene.far, (height, width), jnp.float32)
    if segmentation:
        spaces["segmentation"] = Box(-1, max(model.ngeom, model.nsite), (height, width, 2), jnp.int32)
    name = f"camera({scene.camera_names[camera_id] or camera_id}, {height}x{width})"
    if base is None:
        return Sensor(observe=observe, spec=Dict(spaces), name=name)
    return Sensor(observe=observe, spec=Dict(spaces), name=f"{base.name}+{name}", default_params=base.default_params)
