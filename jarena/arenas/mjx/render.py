"""Host-side rendering of MJX physics states with ``mujoco.Renderer`` (``MUJOCO_GL=egl`` headless)."""

from __future__ import annotations

import atexit
import contextlib

import mujoco  # jarena's import chose the GL backend before this (jarena/_headless.py)
import numpy as np


def _close_at_exit(renderer: mujoco.Renderer) -> None:
    """Frees a renderer's GL context at exit; by then EGL may already be shut down, which is harmless."""
    with contextlib.suppress(Exception):  # OpenGL's EGLError: EGL_NOT_INITIALIZED at interpreter exit
        renderer.close()


class _Frames:
    """A model's renderer and scratch MjData, created on the first frame and reused."""

    def __init__(self, model: mujoco.MjModel):
        self.model = model
        self.data = None
        self.renderers: dict[tuple[int, int], mujoco.Renderer] = {}

    def __call__(self, physics, params=None, *, width: int = 320, height: int = 240,
                 camera: int | str = -1) -> np.ndarray:
        """Renders one arena's physics (an ``mjx.Data`` of one arena) to uint8 (height, width, 3)."""
        m = self.model
        if self.data is None:
            self.data = mujoco.MjData(m)
        d = self.data
        d.qpos[:] = np.asarray(physics.qpos)
        d.qvel[:] = np.asarray(physics.qvel)
        if m.nmocap:
            d.mocap_pos[:] = np.asarray(physics.mocap_pos)
            d.mocap_quat[:] = np.asarray(physics.mocap_quat)
        mujoco.mj_forward(m, d)
        key = (int(height), int(width))
        if key not in self.renderers:
            if height > m.vis.global_.offheight or width > m.vis.global_.offwidth:
                m.vis.global_.offheight = max(m.vis.global_.offheight, height)
                m.vis.global_.offwidth = max(m.vis.global_.offwidth, width)
            self.renderers[key] = mujoco.Renderer(m, height, width)
            # free the GL contexts at exit before MuJoCo's EGL display is terminated (registered on the
            # first context, so this later registration runs first); avoids errors from __del__ at exit
            atexit.register(_close_at_exit, self.renderers[key])
        renderer = self.renderers[key]
        renderer.update_scene(d, camera=camera)
        return renderer.render().copy()

    def close(self):
        for r in self.renderers.values():
            r.close()
        self.renderers.clear()


def renderer_for(model: mujoco.MjModel) -> _Frames:
    """A ``render(physics, params, *, width, height, camera)`` function for ``Dynamics.render``."""
    return _Frames(model)
