"""Deterministic trajectories for dataset tests: trajectory k's contents are a function of k alone."""

import numpy as np

OBS = {"state": {"shape": (3,)}, "rgb": {"shape": (4, 4, 3), "dtype": "uint8", "output_key": "image"}}
ACT = {"force": {"shape": (2,)}}
GOAL = {"target": {"shape": (2,), "output_key": "goal"}}


def length_of(k: int) -> int:
    return 1 + (7 * k) % 9


def trajectory(k: int, length: int | None = None) -> dict:
    t = length_of(k) if length is None else length
    steps = np.arange(t + 1)
    rgb = ((k * 31 + steps[:, None, None, None] + np.arange(48).reshape(4, 4, 3)) % 256).astype(np.uint8)
    return dict(observations={"state": np.stack([np.full(t + 1, k), steps, -steps], -1).astype(np.float32),
                              "rgb": rgb},
                actions={"force": np.stack([np.full(t, k), np.arange(t)], -1).astype(np.float32)},
                goal={"target": np.array([k, -k], np.float32)}, rewards=np.arange(t, dtype=np.float32) + k,
                terminated=np.arange(t) == t - 1, truncated=np.zeros(t, bool), episode=100 + k)


def check(dataset, k: int, index: int | None = None) -> None:
    """Asserts that trajectory ``index`` (default ``k``) of ``dataset`` is ``trajectory(k)``."""
    want, got = trajectory(k), dataset.get_trajectory(k if index is None else index)
    np.testing.assert_array_equal(got["observation"]["state"], want["observations"]["state"])
    np.testing.assert_array_equal(got["observation"]["image"], want["observations"]["rgb"])
    assert got["observation"]["image"].dtype == np.uint8
    np.testing.assert_array_equal(got["action"]["force"], want["actions"]["force"])
    np.testing.assert_array_equal(got["goal"]["goal"], want["goal"]["target"])
    np.testing.assert_array_equal(got["reward"], want["rewards"])
    np.testing.assert_array_equal(got["terminated"], want["terminated"])
    assert got["episode"] == 100 + k and got["length"] == length_of(k)
