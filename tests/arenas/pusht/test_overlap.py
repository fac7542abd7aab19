"""Exact coverage of the goal T against shapely's polygon intersection (as pusht_env computes it)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import shapely.geometry as sg

from jarena.arenas import pusht
from jarena.arenas.pusht import geometry


def shapely_t(pose) -> sg.MultiPolygon:
    x, y, angle = pose
    c, s = np.cos(angle), np.sin(angle)
    rotation = np.array([[c, -s], [s, c]])
    return sg.MultiPolygon([sg.Polygon(quad.astype(np.float64) @ rotation.T + [x, y])
                            for quad in geometry.box_corners()])


def test_coverage_matches_shapely_on_random_poses():
    """300 poses near the goal (two thirds overlap it) and a goal elsewhere, in one jitted, vmapped call."""
    rng = np.random.default_rng(0)
    poses = np.stack([rng.uniform(150, 360, 300), rng.uniform(150, 360, 300), rng.uniform(-np.pi, np.pi, 300)], -1)
    poses[:4] = [geometry.GOAL_POSE, (256.0, 256.0, 3 * np.pi / 4), (256.0, 276.0, np.pi / 4),
                 (256.0, 256.0, 5 * np.pi / 4)]
    goals = np.tile(np.array(geometry.GOAL_POSE), (300, 1))
    goals[-50:] = [200.0, 300.0, -1.0]
    poses[-50:, :2] -= [56.0, -44.0]
    got = np.asarray(jax.jit(jax.vmap(pusht.coverage))(jnp.float32(poses), jnp.float32(goals)))
    want = np.array([shapely_t(g).intersection(shapely_t(p)).area / geometry.AREA
                     for p, g in zip(poses, goals, strict=True)])
    np.testing.assert_allclose(got, want, atol=1e-4)
    # at the goal; turned a quarter about the bar's middle (the bars cross: 2 x 30 x 30 + 30 x 60 = 1800 of 6300);
    # shifted along y; turned half a turn (the Ts touch along the bar's outer edge only)
    np.testing.assert_allclose(got[:4], [1.0, 1800 / 6300, want[2], 0.0], atol=1e-5)
    assert np.mean(want > 0) > 0.5 and np.mean(want == 0) > 0.1


def test_default_goal_is_pusht_envs():
    assert float(jax.jit(pusht.coverage)(jnp.asarray(geometry.GOAL_POSE))) > 1 - 1e-5
    assert abs(geometry.AREA - shapely_t(geometry.GOAL_POSE).area) < 1e-6
