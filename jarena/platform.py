"""Work-arounds for the platform JAX runs on."""

from __future__ import annotations

import os

_FLAG = "--xla_cpu_multi_thread_eigen=false"


def default_headless_gl() -> None:
    """Selects MuJoCo's headless EGL rendering (``MUJOCO_GL=egl``) unless the user chose a backend.

    MuJoCo picks its OpenGL backend when ``mujoco`` is first imported, so this runs when jarena is
    imported, before any arena imports mujoco. Only on Linux, where EGL is the headless backend (GPU
    machines and CPU-only servers alike); elsewhere MuJoCo's default (the desktop's GL) stays.
    """
    import sys

    if sys.platform.startswith("linux"):
        os.environ.setdefault("MUJOCO_GL", "egl")


def avoid_cpu_eigen_deadlock(force: bool = False) -> bool:
    """Turns off XLA:CPU's multi-threaded Eigen kernels on machines with at most 2 CPUs (or ``force``).

    On 2-core machines XLA:CPU (jaxlib 0.10) can deadlock when concurrently scheduled operations and
    Eigen's parallel kernels share its small thread pool: every thread waits and the computation never
    finishes (seen with seed-vmapped PPO training). Single-threaded Eigen kernels avoid it at little
    cost for the small networks used there. Must run before JAX creates its CPU backend (the first
    computation); returns whether the flag is set.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_multi_thread_eigen" in flags:
        return _FLAG in flags
    if force or (os.cpu_count() or 1) <= 2:
        os.environ["XLA_FLAGS"] = (flags + " " + _FLAG).strip()
        return True
    return False
