"""Ray-primitive intersections against MuJoCo's own ``mju_rayGeom`` on random rays, primitives and poses."""

import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from jarena.arenas.mjx import raycast


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, q)
    return mat.reshape(3, 3)


def random_size(kind, rng):
    size = rng.uniform(0.05, 0.6, size=3)
    if kind == "plane":
        size[:2] = rng.choice([0.0, 0.5, 2.0], size=2)
    return size


@pytest.mark.parametrize("kind", list(raycast.INTERSECT))
def test_intersections_and_normals_match_mujoco(kind):
    rng = np.random.default_rng(list(raycast.INTERSECT).index(kind))
    geomtype = getattr(mujoco.mjtGeom, f"mjGEOM_{kind.upper()}")
    n = 400
    origins, directions, sizes, mats, positions, expected, expected_normals = [], [], [], [], [], [], []
    for _ in range(n):
        pos = rng.normal(size=3) * 0.3
        mat = random_rotation(rng)
        size = random_size(kind, rng)
        # origins outside the primitive's bounding sphere, aimed near it so that about half the rays hit
        bound = 2.0 * np.linalg.norm(size) + 0.1
        u = rng.normal(size=3)
        origin = pos + u / np.linalg.norm(u) * rng.uniform(bound, 3 * bound)
        if kind == "plane":
            origin = pos + mat @ np.array([*rng.normal(size=2), rng.uniform(0.2, 2.0)])
        direction = pos + rng.normal(size=3) * 0.5 * np.max(size) - origin
        direction *= rng.uniform(0.5, 2.0)  # t is in units of the direction's length
        normal = np.zeros(3)
        t = mujoco.mju_rayGeom(pos, mat.ravel(), size, origin, direction, geomtype, normal)
        origins.append(origin), directions.append(direction), sizes.append(size), mats.append(mat)
        positions.append(pos), expected.append(t), expected_normals.append(normal)
    origins, directions, sizes, mats, positions = map(np.array, (origins, directions, sizes, mats, positions))
    o_local = np.einsum("ni,nij->nj", origins - positions, mats)
    d_local = np.einsum("ni,nij->nj", directions, mats)
    t = np.asarray(raycast.INTERSECT[kind](jnp.asarray(o_local, jnp.float32), jnp.asarray(d_local, jnp.float32),
                                           jnp.asarray(sizes, jnp.float32)))
    expected = np.array(expected)
    hit_mj, hit = expected >= 0, np.isfinite(t)
    assert 0.1 < hit_mj.mean() < 0.9  # the test draws both hits and misses
    assert np.array_equal(hit, hit_mj), f"{np.sum(hit != hit_mj)} of {n} rays disagree on hitting the {kind}"
    np.testing.assert_allclose(t[hit], expected[hit], rtol=1e-4, atol=1e-5)
    point = o_local[hit] + t[hit, None] * d_local[hit]
    normal = np.asarray(raycast.normal(kind, jnp.asarray(point, jnp.float32), jnp.asarray(sizes[hit], jnp.float32)))
    normal = np.einsum("nij,nj->ni", mats[hit], normal)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    np.testing.assert_allclose(normal, np.array(expected_normals)[hit], atol=2e-3)


def test_unknown_primitive_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown primitive 'mesh'; choose from plane, sphere"):
        raycast.normal("mesh", jnp.zeros((1, 3)), jnp.ones((1, 3)))
