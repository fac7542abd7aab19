"""Test configuration: JAX's persistent compilation cache keeps the suite fast on small CPU machines."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; also keeps dm_control from probing X11

from jarena.platform import avoid_cpu_eigen_deadlock

avoid_cpu_eigen_deadlock(force=True)  # before JAX starts its CPU backend

import jax  # noqa: E402

jax.config.update("jax_compilation_cache_dir",
                  os.environ.get("JARENA_JAX_CACHE", os.path.expanduser("~/.cache/jarena/jax")))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
