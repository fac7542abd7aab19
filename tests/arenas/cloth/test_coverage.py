"""SoftGym's coverage metric against an independent host rasterisation (matplotlib paths)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from matplotlib.path import Path

from jarena.arenas.cloth import coverage
from jarena.arenas.cloth.mesh import ClothMesh

MESH = ClothMesh(rows=20, cols=20, spacing=0.02)  # 0.38 m square


def host_coverage(positions, triangles, n=1024):
    """Area in m^2 of the union of the triangles' x-y projections, by testing the centres of an ``n x n``
    grid over the bounding box with matplotlib (each triangle on the grid points of its own box)."""
    xy = np.asarray(positions, np.float64)[:, :2]
    lo, hi = xy.min(0), xy.max(0)
    step = (hi - lo) / n
    hit = np.zeros((n, n), bool)
    for tri in np.asarray(triangles):
        v = xy[tri]
        c0, r0 = np.floor((v.min(0) - lo) / step).astype(int)
        c1, r1 = np.ceil((v.max(0) - lo) / step).astype(int) + 1
        c0, r0, c1, r1 = max(c0, 0), max(r0, 0), min(c1, n), min(r1, n)
        cols, rows = np.meshgrid(np.arange(c0, c1), np.arange(r0, r1))
        pts = lo + (np.stack([cols.ravel(), rows.ravel()], -1) + 0.5) * step
        inside = Path(v).contains_points(pts)
        hit[rows.ravel()[inside], cols.ravel()[inside]] = True
    return hit.sum() * step[0] * step[1]


def grid(mesh=MESH):
    return mesh.rest_positions.reshape(mesh.rows, mesh.cols, 3).astype(np.float64)


def rotate(p, degrees, shift=(0.0, 0.0)):
    a = np.deg2rad(degrees)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    p = p.copy()
    p[..., :2] = p[..., :2] @ rot.T + np.asarray(shift)
    return p


def fold(p, k, gap, axis=0):
    """The flat grid (rows, cols, 3) folded: rows (axis 0) or columns (axis 1) beyond ``k`` reflected about
    row (column) ``k`` onto the rest, ``gap`` metres above it."""
    p = np.swapaxes(p, 0, axis).copy()  # rows first
    coord = 1 - axis  # rows run along y, columns along x
    p[k + 1:, :, coord] = 2 * p[k, 0, coord] - p[k + 1:, :, coord]
    p[k + 1:, :, 2] += gap
    return np.swapaxes(p, 0, axis)


def crumple(p, seed, shrink=1.0, amplitude=0.006, bumps=0.03):
    """Shrunk in x-y about its middle, then smooth random in-plane displacement, smooth random heights and a
    little height noise."""
    rng = np.random.default_rng(seed)
    p = p.copy()
    p[..., :2] = p[..., :2].mean((0, 1)) + shrink * (p[..., :2] - p[..., :2].mean((0, 1)))
    x, y = p[..., 0].copy(), p[..., 1].copy()
    for _ in range(4):
        kx, ky, phase = rng.normal(0, 10, 3)
        p[..., 0] += amplitude * np.sin(kx * x + ky * y + phase)
        p[..., 1] += amplitude * np.cos(ky * x - kx * y + phase)
        p[..., 2] += bumps * (1 + np.sin(kx * y - ky * x + phase)) / 2
    p[..., 2] += 0.002 * rng.normal(size=x.shape)
    return p


def max_stretch(positions, mesh=MESH):
    """Largest triangle edge over its rest length (the coverage window holds up to 1.5)."""
    p, rest = np.asarray(positions).reshape(-1, 3), mesh.rest_positions.astype(np.float64)
    tri = mesh.triangles
    edge = lambda q: np.linalg.norm(q[tri] - q[tri[:, [1, 2, 0]]], axis=-1)
    return float((edge(p) / edge(rest)).max())


@functools.cache
def compiled(mesh=MESH, cell=coverage.CELL):
    return jax.jit(lambda p: coverage.coverage(p, mesh, cell))


def measure(p, mesh=MESH):
    positions = np.asarray(p, np.float32).reshape(-1, 3)
    return float(compiled(mesh)(positions)), host_coverage(positions, mesh.triangles)


def test_flat_cloth_covers_its_area():
    got, host = measure(grid())
    assert got == pytest.approx(MESH.area, rel=0.01)
    assert got == pytest.approx(host, rel=0.01)
    assert float(coverage.normalised_coverage(grid().reshape(-1, 3), MESH)) == pytest.approx(1.0, abs=0.01)


def test_rotated_and_shifted_flat_cloth():
    p = rotate(grid(), 30.0, shift=(0.7, -1.3))
    p[..., 2] += 0.25
    got, host = measure(p)
    assert got == pytest.approx(host, rel=0.01)
    assert got == pytest.approx(MESH.area, rel=0.01)


def test_cloth_folded_in_half_covers_half():
    p = fold(grid(), MESH.rows // 2 - 1, 0.01)  # rows 10..19 onto rows 8..-1: about half the area
    got, host = measure(p)
    assert got == pytest.approx(host, rel=0.01)
    assert got == pytest.approx(MESH.area * 10 / 19, rel=0.02)
    assert float(coverage.normalised_coverage(p.reshape(-1, 3), MESH)) == pytest.approx(10 / 19, rel=0.02)


@pytest.mark.parametrize("seed", [0, 1])
def test_crumpled_cloth(seed):
    if seed == 0:  # pushed together into bumps
        p = rotate(crumple(grid(), seed, shrink=0.85), 17.0)
    else:  # folded once along each axis, then crumpled
        p = rotate(crumple(fold(fold(grid(), 13, 0.01), 12, 0.012, axis=1), seed), -40.0, (0.3, 0.1))
    assert max_stretch(p) < 1.5  # within what the window holds
    got, host = measure(p)
    assert got == pytest.approx(host, rel=0.01)
    assert got < MESH.area * (0.8 if seed == 0 else 0.6)


def test_stretched_cloth_at_the_grid_bound_still_fits():
    # 1.19 x the rest size turned 45 degrees: extents of 1.19 x the diagonal, the grid holds 1.2 x.
    p = rotate(grid() * 1.19, 45.0, shift=(-2.0, 3.0))
    got, host = measure(p)
    assert got == pytest.approx(host, rel=0.01)
    assert got == pytest.approx(MESH.area * 1.19**2, rel=0.01)
    assert float(coverage.normalised_coverage(p.reshape(-1, 3), MESH)) == 1.0  # clipped


def test_static_sizes():
    mesh = ClothMesh.of_size(0.4, 0.4, cols=40)
    assert coverage.grid_size(mesh) == int(np.ceil(1.2 * np.hypot(0.4, 0.4) / 0.004)) + 2 == 172
    assert coverage.coverage_window(mesh) == int(np.floor(1.5 * np.sqrt(2) * mesh.spacing / 0.004)) + 1 == 6
    assert coverage.coverage_window(MESH, cell=0.01) == 5


def test_cell_size_is_a_parameter():
    p = rotate(grid(), 30.0)
    coarse = float(jax.jit(lambda q: coverage.coverage(q, MESH, 0.01))(p.reshape(-1, 3).astype(np.float32)))
    assert coarse == pytest.approx(MESH.area, rel=0.05)


def test_batches_match_single_runs_under_jit():
    ps = np.stack([grid(), fold(grid(), 9, 0.01), crumple(grid(), 3)]).reshape(3, -1, 3).astype(np.float32)
    batched = jax.jit(jax.vmap(lambda p: coverage.coverage(p, MESH)))(ps)
    one = jax.jit(jax.vmap(lambda p: coverage.coverage(p, MESH)))(ps[:1])
    singles = [float(compiled()(p)) for p in ps]
    eager = float(coverage.coverage(jnp.asarray(ps[2]), MESH))
    np.testing.assert_array_equal(np.asarray(batched), np.asarray(singles, np.float32))
    assert float(one[0]) == singles[0] and eager == singles[2]
    assert batched.dtype == jnp.float32 and batched.shape == (3,)
    norm = jax.vmap(lambda p: coverage.normalised_coverage(p, MESH))(ps)
    np.testing.assert_allclose(np.asarray(norm), np.minimum(np.asarray(singles) / MESH.area, 1.0), rtol=1e-6)
