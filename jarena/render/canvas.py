"""A tiny numpy raster canvas in world coordinates (y up), for the 2-D classic-control renderers.

No anti-aliasing: a pixel is painted when its centre lies inside the shape. Each primitive touches only
the pixels of its bounding box, so a frame of a few shapes costs well under a millisecond at 320 x 240.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

Color = tuple[int, int, int]


class Canvas:
    """An RGB uint8 image of ``height`` x ``width`` pixels showing the world box ``xlim`` x ``ylim``.

    The box is scaled uniformly (square pixels) to fit and centred; world ``y`` points up.
    """

    def __init__(self, width: int, height: int, xlim: tuple[float, float], ylim: tuple[float, float],
                 background: Color = (255, 255, 255)):
        if int(width) < 1 or int(height) < 1:
            raise ValueError(f"canvas size must be positive, got width={width}, height={height}")
        self.width, self.height = int(width), int(height)
        self.image = np.empty((self.height, self.width, 3), np.uint8)
        self.image[:] = background
        span_x, span_y = xlim[1] - xlim[0], ylim[1] - ylim[0]
        self.scale = min(self.width / span_x, self.height / span_y)  # pixels per world unit
        # world point at the image centre
        self.cx, self.cy = (xlim[0] + xlim[1]) / 2, (ylim[0] + ylim[1]) / 2

    # ------------------------------------------------------------------ coordinates
    def to_pixels(self, points) -> np.ndarray:
        """World (..., 2) -> pixel (..., 2) as (column, row), continuous."""
        p = np.asarray(points, np.float64)
        col = (p[..., 0] - self.cx) * self.scale + self.width / 2
        row = self.height / 2 - (p[..., 1] - self.cy) * self.scale
        return np.stack([col, row], -1)

    def _box(self, pixels: np.ndarray, pad: float):
        """Index ranges and pixel-centre grids of the bounding box of ``pixels`` (n, 2) grown by ``pad``."""
        c0 = max(int(np.floor(pixels[:, 0].min() - pad)), 0)
        c1 = min(int(np.ceil(pixels[:, 0].max() + pad)) + 1, self.width)
        r0 = max(int(np.floor(pixels[:, 1].min() - pad)), 0)
        r1 = min(int(np.ceil(pixels[:, 1].max() + pad)) + 1, self.height)
        if c0 >= c1 or r0 >= r1:
            return None
        cols = np.arange(c0, c1) + 0.5
        rows = np.arange(r0, r1)[:, None] + 0.5
        return (slice(r0, r1), slice(c0, c1)), cols, rows

    def _paint(self, box, mask, color: Color):
        self.image[box][mask] = color

    # ------------------------------------------------------------------ primitives
    def polygon(self, points: Sequence, color: Color) -> Canvas:
        """Fills a convex polygon given by its corners (n, 2) in world units, in either winding order."""
        pix = self.to_pixels(points)
        found = self._box(pix, 0.0)
        if found is None:
            return self
        box, cols, rows = found
        area = np.sum(pix[:, 0] * np.roll(pix[:, 1], -1) - np.roll(pix[:, 0], -1) * pix[:, 1])
        sign = 1.0 if area >= 0 else -1.0
        inside = np.ones((rows.shape[0], cols.shape[0]), bool)
        for (x0, y0), (x1, y1) in zip(pix, np.roll(pix, -1, axis=0), strict=True):
            inside &= sign * ((x1 - x0) * (rows - y0) - (y1 - y0) * (cols - x0)) >= 0
        self._paint(box, inside, color)
        return self

    def rectangle(self, center, size, color: Color, angle: float = 0.0) -> Canvas:
        """Fills a ``size = (w, h)`` rectangle centred at ``center``, rotated ``angle`` rad counter-clockwise."""
        w, h = size[0] / 2, size[1] / 2
        if angle == 0:  # axis-aligned: fill the pixels whose centres lie inside directly
            (c0, r1), (c1, r0) = self.to_pixels([[center[0] - w, center[1] - h], [center[0] + w, center[1] + h]])
            rows = slice(max(int(np.ceil(r0 - 0.5)), 0), max(int(np.ceil(r1 - 0.5)), 0))
            cols = slice(max(int(np.ceil(c0 - 0.5)), 0), max(int(np.ceil(c1 - 0.5)), 0))
            self.image[rows, cols] = color
            return self
        corners = np.array([[-w, -h], [w, -h], [w, h], [-w, h]])
        c, s = np.cos(angle), np.sin(angle)
        corners = corners @ np.array([[c, s], [-s, c]]) + np.asarray(center, np.float64)
        return self.polygon(corners, color)

    def disk(self, center, radius: float, color: Color) -> Canvas:
        """Fills a disk (radius in world units; at least half a pixel)."""
        pix = self.to_pixels(np.asarray(center, np.float64)[None])
        r = max(radius * self.scale, 0.5)
        found = self._box(pix, r)
        if found is None:
            return self
        box, cols, rows = found
        self._paint(box, (cols - pix[0, 0]) ** 2 + (rows - pix[0, 1]) ** 2 <= r * r, color)
        return self

    def line(self, start, end, width: float, color: Color) -> Canvas:
        """Draws a segment with round caps, ``width`` in world units (at least one pixel)."""
        pix = self.to_pixels(np.stack([np.asarray(start, np.float64), np.asarray(end, np.float64)]))
        half = max(width * self.scale, 1.0) / 2
        found = self._box(pix, half)
        if found is None:
            return self
        box, cols, rows = found
        (x0, y0), (x1, y1) = pix
        dx, dy = x1 - x0, y1 - y0
        t = ((cols - x0) * dx + (rows - y0) * dy) / max(dx * dx + dy * dy, 1e-12)
        t = np.clip(t, 0.0, 1.0)
        self._paint(box, (cols - x0 - t * dx) ** 2 + (rows - y0 - t * dy) ** 2 <= half * half, color)
        return self

    def graph(self, f, x0: float, x1: float, width: float, color: Color) -> Canvas:
        """Draws the curve ``y = f(x)`` for ``x0 <= x <= x1`` (``f`` vectorised over numpy arrays), one pixel
        column at a time: each column is painted between its and its neighbours' heights, ``width`` thick."""
        c0, c1 = self.to_pixels([[x0, 0.0], [x1, 0.0]])[:, 0]
        cols = np.arange(max(int(np.ceil(c0 - 0.5)), 0), min(int(np.ceil(c1 - 0.5)), self.width))
        if cols.size == 0:
            return self
        xs = (cols + 0.5 - self.width / 2) / self.scale + self.cx
        rows = self.height / 2 - (np.asarray(f(xs), np.float64) - self.cy) * self.scale
        prev, nxt = np.concatenate([rows[:1], rows[:-1]]), np.concatenate([rows[1:], rows[-1:]])
        half = max(width * self.scale, 1.0) / 2
        low = np.minimum(rows, (rows + np.minimum(prev, nxt)) / 2) - half
        high = np.maximum(rows, (rows + np.maximum(prev, nxt)) / 2) + half
        centres = np.arange(self.height)[:, None] + 0.5
        mask = (centres >= low) & (centres <= high)
        self.image[:, cols[0]: cols[-1] + 1][mask] = color
        return self

    def polyline(self, points: Sequence, width: float, color: Color) -> Canvas:
        """Draws connected segments through ``points`` (n, 2)."""
        points = np.asarray(points, np.float64)
        for a, b in zip(points[:-1], points[1:], strict=True):
            self.line(a, b, width, color)
        return self
