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


#: Values of ``JARENA_COMPILATION_CACHE`` that turn the command line's persistent cache off.
_OFF = ("0", "off", "false", "no", "none")


def enable_compilation_cache(min_compile_secs: float = 1.0) -> str | None:
    """Turns on JAX's persistent compilation cache for a command-line run; returns its directory or None.

    MJX arenas take tens of seconds to compile (humanoid: 20-60 s on a GPU); with the cache, running the
    same agent and arena again loads the compiled programs from disk. Programs that compiled in less
    than ``min_compile_secs`` are not stored. A directory the user already gave JAX (``jax.config`` or
    ``JAX_COMPILATION_CACHE_DIR``) is kept. Otherwise the directory is ``JARENA_COMPILATION_CACHE``, or
    ``$XDG_CACHE_HOME/jarena/xla`` (``~/.cache/jarena/xla``) by default; set that variable to ``off`` to
    turn the cache off. Entry points call this; importing jarena changes no JAX setting.
    """
    import jax

    if jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    setting = os.environ.get("JARENA_COMPILATION_CACHE", "").strip()
    if setting.lower() in _OFF:
        return None
    cache_home = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    path = os.path.abspath(os.path.expanduser(setting or os.path.join(cache_home, "jarena", "xla")))
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_secs))
    return path
