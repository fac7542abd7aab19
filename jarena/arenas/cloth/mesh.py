"""The cloth's particle grid: sizes, rest positions, triangles and the constraint pairs between particles.

A cloth of ``rows x cols`` particles with ``spacing`` metres between grid neighbours; particle ``(i, j)``
(row ``i``, column ``j``) has flat index ``i * cols + j``. The world is z-up (as MuJoCo's): the flat cloth
lies in the x-y plane, rows along y and columns along x. All arrays here are static numpy arrays, computed
once per mesh, so they are constants under ``jit``.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np


@dataclasses.dataclass(frozen=True)
class ClothMesh:
    """A rectangular particle grid.

    Attributes:
      rows: particles along y (at least 2).
      cols: particles along x (at least 2).
      spacing: metres between grid neighbours at rest.
    """

    rows: int
    cols: int
    spacing: float

    def __post_init__(self):
        if int(self.rows) < 2 or int(self.cols) < 2:
            raise ValueError(f"a cloth needs at least 2 x 2 particles, got {self.rows} x {self.cols}")
        if not self.spacing > 0:
            raise ValueError(f"cloth particle spacing must be positive, got {self.spacing}")

    @classmethod
    def of_size(cls, width: float, height: float, particles_per_metre: float | None = None,
                cols: int | None = None) -> ClothMesh:
        """A mesh ``width x height`` metres (x by y) with ``cols`` particles along x (rows follow)."""
        if not (width > 0 and height > 0):
            raise ValueError(f"cloth size must be positive, got {width} x {height} m")
        if cols is None:
            cols = max(2, round(width * particles_per_metre) + 1)
        spacing = width / (cols - 1)
        rows = max(2, round(height / spacing) + 1)
        return cls(rows=int(rows), cols=int(cols), spacing=float(spacing))

    @property
    def num_particles(self) -> int:
        return self.rows * self.cols

    @property
    def width(self) -> float:
        """Extent along x at rest, metres."""
        return (self.cols - 1) * self.spacing

    @property
    def height(self) -> float:
        """Extent along y at rest, metres."""
        return (self.rows - 1) * self.spacing

    @property
    def area(self) -> float:
        """Area of the flat mesh, square metres (what a perfectly flat cloth covers from above)."""
        return self.width * self.height

    def index(self, i: int, j: int) -> int:
        return i * self.cols + j

    @functools.cached_property
    def rest_positions(self) -> np.ndarray:
        """float32 (N, 3): the flat cloth centred at the origin at z = 0."""
        y, x = np.meshgrid(np.arange(self.rows), np.arange(self.cols), indexing="ij")
        pos = np.stack([x * self.spacing - self.width / 2, y * self.spacing - self.height / 2,
                        np.zeros_like(x, dtype=float)], axis=-1)
        return pos.reshape(-1, 3).astype(np.float32)

    @functools.cached_property
    def corners(self) -> np.ndarray:
        """int32 (4,): flat indices of the corners, counter-clockwise from (row 0, col 0) seen from +z."""
        r, c = self.rows - 1, self.cols - 1
        return np.array([self.index(0, 0), self.index(0, c), self.index(r, c), self.index(r, 0)], np.int32)

    @functools.cached_property
    def triangles(self) -> np.ndarray:
        """int32 (T, 3), T = 2 (rows - 1) (cols - 1): counter-clockwise seen from +z when flat, so a
        triangle's normal ``cross(b - a, c - a)`` points up (+z) on the cloth's front face."""
        i, j = np.meshgrid(np.arange(self.rows - 1), np.arange(self.cols - 1), indexing="ij")
        a = (i * self.cols + j).ravel()
        b, c, d = a + 1, a + self.cols + 1, a + self.cols
        return np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).astype(np.int32)
