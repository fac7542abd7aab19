"""Imported first by ``jarena``: selects MuJoCo's headless GL backend before any arena imports mujoco
(see :func:`jarena.platform.default_headless_gl`)."""

from jarena.platform import default_headless_gl

default_headless_gl()
