import os
import sys

import pytest

from jarena.platform import default_headless_gl


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="EGL is chosen on Linux only")
def test_headless_gl_is_the_default_and_a_users_choice_is_kept(monkeypatch):
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    default_headless_gl()
    assert os.environ["MUJOCO_GL"] == "egl"
    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    default_headless_gl()
    assert os.environ["MUJOCO_GL"] == "osmesa"
