import os
import subprocess
import sys

import pytest

from jarena.platform import default_headless_gl, enable_compilation_cache


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="EGL is chosen on Linux only")
def test_headless_gl_is_the_default_and_a_users_choice_is_kept(monkeypatch):
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    default_headless_gl()
    assert os.environ["MUJOCO_GL"] == "egl"
    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    default_headless_gl()
    assert os.environ["MUJOCO_GL"] == "osmesa"


@pytest.fixture
def no_cache_configured(monkeypatch):
    """JAX with no persistent cache directory for the test (the suite's own is restored after)."""
    import jax

    saved = (jax.config.jax_compilation_cache_dir, jax.config.jax_persistent_cache_min_compile_time_secs)
    jax.config.update("jax_compilation_cache_dir", None)
    monkeypatch.delenv("JARENA_COMPILATION_CACHE", raising=False)
    yield jax.config
    jax.config.update("jax_compilation_cache_dir", saved[0])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", saved[1])


def test_compilation_cache_defaults_under_the_user_cache_home(no_cache_configured, monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert enable_compilation_cache(2.5) == str(tmp_path / "jarena" / "xla")
    assert no_cache_configured.jax_compilation_cache_dir == str(tmp_path / "jarena" / "xla")
    assert no_cache_configured.jax_persistent_cache_min_compile_time_secs == 2.5


@pytest.mark.parametrize("off", ["off", "0", "False", "none"])
def test_compilation_cache_can_be_turned_off(no_cache_configured, monkeypatch, off):
    monkeypatch.setenv("JARENA_COMPILATION_CACHE", off)
    assert enable_compilation_cache() is None
    assert no_cache_configured.jax_compilation_cache_dir is None


def test_a_cache_directory_the_user_chose_is_kept(no_cache_configured, monkeypatch, tmp_path):
    no_cache_configured.update("jax_compilation_cache_dir", str(tmp_path / "mine"))
    monkeypatch.setenv("JARENA_COMPILATION_CACHE", str(tmp_path / "ours"))
    assert enable_compilation_cache() == str(tmp_path / "mine")
    assert no_cache_configured.jax_compilation_cache_dir == str(tmp_path / "mine")


def test_the_cache_stores_compiled_programs_and_a_new_process_loads_them(tmp_path):
    """Two runs of one script in fresh processes: the first writes cache entries, the second reads them."""
    cache = tmp_path / "cache"
    script = ("from jarena.platform import enable_compilation_cache\n"
              "print(enable_compilation_cache(min_compile_secs=0))\n"
              "import jax, jax.numpy as jnp\n"
              "hits = []\n"
              "jax.monitoring.register_event_listener("
              "lambda event, **kw: hits.append(event) if event.endswith('cache_hits') else None)\n"
              "print(float(jax.jit(lambda x: jnp.sin(x).sum() * 3)(jnp.arange(5.0))), len(hits))\n")
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    env.update(JARENA_COMPILATION_CACHE=str(cache), JAX_PLATFORMS="cpu")
    first = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    where, value, hits = first.stdout.split()
    assert where == str(cache) and hits == "0"
    assert any(cache.iterdir()), "no compiled program was stored"
    second = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    assert second.stdout.split()[1] == value
    assert int(second.stdout.split()[2]) >= 1  # the program was loaded from the cache


def test_the_command_line_turns_the_cache_on(monkeypatch, capsys):
    import jarena.platform
    from jarena.cli import main

    calls = []
    monkeypatch.setattr(jarena.platform, "enable_compilation_cache", lambda *a, **k: calls.append(a))
    assert main(["list"]) == 0
    assert calls == [()]
