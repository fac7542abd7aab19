"""SoftGym's coverage metric: the area of the cloth's top-down (orthographic, along z) projection.

Computed from the particles alone, independently of any camera: the triangles' x-y projections are
rasterised (:func:`jarena.arenas.cloth.raster.covered`) onto a square world grid of ``n x n`` cells of
``cell`` metres, and the cells whose centre some triangle covers are counted. Overlapping layers count
once, so a cloth folded in half covers about half its area.

Grid: ``n = ceil(1.2 * diagonal / cell) + 2`` cells per side, ``diagonal`` being the flat mesh's
``sqrt(width^2 + height^2)``, centred (up to a quarter cell) on the middle of the particles' x-y bounding
box. Every cloth whose x and y extents (max minus min over the particles) are at most 1.2 times its rest
diagonal therefore lies wholly inside the grid; a flat cloth at any rotation has extents of at most its
diagonal, so this leaves 20 % for stretching. Parts of a cloth spread wider are cut off (under-counted).
The bounding box's middle rather than the particles' mean is what makes the bound hold for any shape at
this size: a particle may be almost the whole extent away from the mean, so a mean-centred grid would
need twice the side (four times the cells) for the same guarantee. The quarter-cell shift keeps cell
centres off the outline of axis-aligned (and 45-degree) cloths of common sizes: counting the centres in
an interval of length ``w`` centred a quarter cell off a cell centre errs by at most half a cell, against
a whole cell when the interval's ends fall on cell centres.

Window (see ``raster``): a triangle's extent along x or y is at most its longest edge, at most
``stretch * sqrt(2) * spacing`` for a grid mesh stretched by up to ``stretch`` (1.5 by default), so the
window is ``floor(stretch * sqrt(2) * spacing / cell) + 1`` cells; triangles stretched further may lose
cells. Cost per cloth: ``T * window^2`` candidate cells and an ``n x n`` bool grid; for a 0.4 m, 40 x 40
cloth at 4 mm cells that is 3042 * 36 candidates and a 172 x 172 grid.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from jarena.arenas.cloth import raster
from jarena.arenas.cloth.mesh import ClothMesh

CELL = 0.004  # metres
MAX_EXTENT = 1.2  # the grid holds cloths up to this times the rest diagonal along x and y
STRETCH = 1.5  # the window holds triangles whose edges are up to this times their rest length
OFFSET = 0.25  # cells the grid is shifted from the bounding box's centre (see the module doc)


def grid_size(mesh: ClothMesh, cell: float = CELL, max_extent: float = MAX_EXTENT) -> int:
    """Cells per side of the static coverage grid: ``ceil(max_extent * diagonal / cell) + 2``."""
    if not cell > 0:
        raise ValueError(f"coverage cell must be positive, got {cell}")
    diagonal = math.hypot(mesh.width, mesh.height)
    return int(math.ceil(max_extent * diagonal / cell)) + 2


def coverage_window(mesh: ClothMesh, cell: float = CELL, stretch: float = STRETCH) -> int:
    """Static raster window in cells: ``floor(stretch * sqrt(2) * spacing / cell) + 1``."""
    return raster.window_for(stretch * math.sqrt(2.0) * mesh.spacing / cell)


def coverage(positions, mesh: ClothMesh, cell: float = CELL) -> jax.Array:
    """float32 (): area in square metres of the x-y projection of the cloth.

    Args:
      positions: float32 (N, 3) particle positions, metres (N = mesh.num_particles).
      mesh: the cloth's mesh (static).
      cell: static grid cell size, metres; cells on the outline are counted or not by their centre, so the
        error is at most about the outline's length times ``cell``, and far less on average.
    """
    n = grid_size(mesh, cell)
    window = coverage_window(mesh, cell)
    xy = jnp.asarray(positions, jnp.float32)[:, :2]
    centre = (jnp.min(xy, axis=0) + jnp.max(xy, axis=0)) / 2
    origin = centre - (n / 2 - OFFSET) * cell  # world x-y of the grid's corner (column 0, row 0)
    cells = (xy - origin) / cell  # continuous cell coordinates: x along columns, y along rows
    tri = cells[jnp.asarray(mesh.triangles)]  # (T, 3, 2)
    hit = raster.covered(tri, (n, n), window)
    return jnp.sum(hit, dtype=jnp.int32).astype(jnp.float32) * jnp.float32(cell * cell)


def normalised_coverage(positions, mesh: ClothMesh, cell: float = CELL) -> jax.Array:
    """float32 (): :func:`coverage` over the flat cloth's area (``mesh.area``), clipped to [0, 1]."""
    return jnp.clip(coverage(positions, mesh, cell) / jnp.float32(mesh.area), 0.0, 1.0)
