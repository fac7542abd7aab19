"""How Transporter's pixels meet an arena: which observations make its image, and what its action means.

Transporter thinks in one image's pixels: it picks pixel ``(pick_row, pick_col)`` and places it at ``(place_row,
place_col)`` turned by ``place_yaw`` radians, float32 (5,) (:mod:`jarena_agents.transporter.agent`). An arena's
action is one of two frames (:data:`FRAMES`), read from its action spec (``action_frame: auto``) or named in the
config:

- ``pixels``: the arena acts with exactly that (5,) in its image's pixels (rows 0 .. H - 1, columns 0 .. W - 1) and
  radians: the Raven arenas.
- ``image_points``: the arena acts with one pick and one place point in normalised image coordinates, float32 (4,)
  ``(pick_u, pick_v, place_u, place_v)`` in [-1, 1]: ``u`` from the left edge of the image (-1) to its right edge
  (+1), ``v`` from the top edge to the bottom edge, so pixel ``(r, c)`` of an H x W image has its centre at ``u = (2
  c + 1) / W - 1``, ``v = (2 r + 1) / H - 1`` (:func:`pixels_to_points`; the cloth camera's convention,
  :mod:`jarena.arenas.cloth.camera`): the cloth arenas' ``pixel_pick_and_place(1)``. There is no yaw: the agent's
  is dropped, and configs with ``rotations`` > 1 are refused (the transport would learn to score turns that the
  arena never takes).

The image is the colour ``rgb`` uint8 (H, W, 3) and a height map, float32 (H, W) metres above the table
(:func:`height_map`), from the first of:

- ``height`` (H, W): the height map itself (Raven's heightmaps);
- ``depth`` (H, W): a top-down camera's depth along its axis, metres, whose spec's upper bound is the table's depth
  (the cloth camera's height above the floor, where it draws the floor): height = that bound - depth;
- neither: zeros (a flat table; the colour alone tells the scene).

Every function here is pure and works on one image or action or a batch of them (leading axes), in numpy for numpy
inputs (a dataset read while a program is traced) and in jax.numpy for jax arrays.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.arena import ArenaSpec
from jarena.core.spec import Box
from jarena_agents.config import ConfigError

COLOR_KEY, HEIGHT_KEY, DEPTH_KEY = "rgb", "height", "depth"
"""The observation fields read: the colour image, and a height map or else a depth image."""
FRAMES = ("auto", "pixels", "image_points")
"""Config ``action_frame``: detected from the action spec, or one of the two frames of the module docstring."""


@dataclasses.dataclass(frozen=True)
class Layout:
    """What Transporter reads of an arena (static).

    Attributes:
      shape: the image's (H, W), pixels.
      frame: ``"pixels"`` or ``"image_points"``: the arena's action frame (module docstring).
      height_key: the observation field of the height channel, ``"height"`` or ``"depth"``, or ``None`` (zeros).
      table_depth: with ``depth``, the depth of the table, metres (the depth spec's upper bound); else 0.
    """

    shape: tuple[int, int]
    frame: str
    height_key: str | None = None
    table_depth: float = 0.0

    @property
    def action_size(self) -> int:
        """Values in the arena's action: 5 in pixels, 4 as image points."""
        return 5 if self.frame == "pixels" else 4


# ---------------------------------------------------------------------------------------------- coordinates
def _float32(x):
    """``x`` as float32 in its own array module, and that module: jax.numpy for jax arrays, else numpy."""
    xp = jnp if isinstance(x, jax.Array) else np
    return xp.asarray(x, xp.float32), xp


def pixels_to_points(pixels, shape: tuple[int, int]):
    """float32 (..., 2) normalised image points ``(u, v)`` of ``pixels`` (..., 2) ``(row, column)`` in an image of
    ``shape`` (H, W): ``u = (2 column + 1) / W - 1``, ``v = (2 row + 1) / H - 1`` (a pixel's centre)."""
    pixels, xp = _float32(pixels)
    rows, cols = shape
    return xp.stack([(2 * pixels[..., 1] + 1) / cols - 1, (2 * pixels[..., 0] + 1) / rows - 1], axis=-1)


def points_to_pixels(points, shape: tuple[int, int]):
    """float32 (..., 2) ``(row, column)``, continuous: the inverse of :func:`pixels_to_points` for normalised image
    points ``points`` (..., 2) ``(u, v)``; the nearest pixel is its round."""
    points, xp = _float32(points)
    rows, cols = shape
    return xp.stack([((points[..., 1] + 1) * rows - 1) / 2, ((points[..., 0] + 1) * cols - 1) / 2], axis=-1)


def to_arena_action(action, layout: Layout):
    """The arena's action (..., 4 or 5) for Transporter's (..., 5) ``(pick_row, pick_col, place_row, place_col,
    place_yaw)`` (pixels and radians): unchanged in ``pixels``, the pick's and place's ``(u, v)`` (the yaw dropped)
    as ``image_points``."""
    action, _ = _float32(action)
    if layout.frame == "pixels":
        return action
    points = pixels_to_points(action[..., :4].reshape(action.shape[:-1] + (2, 2)), layout.shape)
    return points.reshape(action.shape[:-1] + (4,))


def from_arena_action(action, layout: Layout):
    """Transporter's (..., 5) pixels and yaw of an arena's action (..., 4 or 5), e.g. a demonstration's: the inverse
    of :func:`to_arena_action` (the yaw 0 for ``image_points``). Pixels are continuous (labels round them)."""
    action, xp = _float32(action)
    if layout.frame == "pixels":
        return action
    pixels = points_to_pixels(action[..., :4].reshape(action.shape[:-1] + (2, 2)), layout.shape)
    return xp.concatenate([pixels.reshape(action.shape[:-1] + (4,)), xp.zeros(action.shape[:-1] + (1,), xp.float32)],
                          -1)


def height_map(observation: dict, layout: Layout):
    """float32 (..., H, W): metres above the table, from ``observation``'s ``layout.height_key`` field (module
    docstring); zeros without one."""
    if layout.height_key == HEIGHT_KEY:
        return _float32(observation[HEIGHT_KEY])[0]
    if layout.height_key == DEPTH_KEY:
        depth, xp = _float32(observation[DEPTH_KEY])
        return xp.float32(layout.table_depth) - depth
    colour = observation[COLOR_KEY]
    xp = jnp if isinstance(colour, jax.Array) else np
    return xp.zeros(colour.shape[:-1], xp.float32)


# ---------------------------------------------------------------------------------------------- detection
def _image_box(space, shape) -> bool:
    return isinstance(space, Box) and tuple(space.shape) == tuple(shape)


def _frames(action, rows: int, cols: int) -> list[str]:
    """The frames (:data:`FRAMES` less ``auto``) that an action spec fits."""
    frames = []
    if isinstance(action, Box) and action.shape == (5,):
        pixels = np.array([rows - 1, cols - 1, rows - 1, cols - 1], np.float64)
        if np.all(np.asarray(action.low)[:4] == 0) and np.all(np.asarray(action.high)[:4] == pixels):
            frames.append("pixels")
    if (isinstance(action, Box) and action.shape == (4,) and np.all(np.asarray(action.low) == -1.0)
            and np.all(np.asarray(action.high) == 1.0)):
        frames.append("image_points")
    return frames


def layout_of(spec: ArenaSpec, frame: str = "auto", rotations: int = 1) -> Layout:
    """The :class:`Layout` of an arena; a ``ConfigError`` naming what does not fit.

    Args:
      spec: the arena's spec: it must observe ``rgb`` uint8 (H, W, 3), and ``height`` or ``depth`` (H, W) if any.
      frame: one of :data:`FRAMES`; ``auto`` takes the one the action spec fits.
      rotations: the config's yaws; more than 1 only for the ``pixels`` frame (the only one with a yaw).
    """
    spaces = getattr(spec.observation, "spaces", {})
    colour = spaces.get(COLOR_KEY)
    if not (isinstance(colour, Box) and colour.dtype == np.uint8 and len(colour.shape) == 3 and colour.shape[2] == 3):
        raise ConfigError(f"transporter reads a top-down colour image {COLOR_KEY!r} uint8 (H, W, 3) and height map "
                          f"{HEIGHT_KEY!r} (H, W) (or a depth image {DEPTH_KEY!r} (H, W), or neither: a flat table); "
                          f"arena {spec.name!r} observes {spec.observation!r}")
    rows, cols = colour.shape[:2]
    height_key, table_depth = None, 0.0
    for key in (HEIGHT_KEY, DEPTH_KEY):
        if key in spaces:
            if not _image_box(spaces[key], (rows, cols)):
                raise ConfigError(f"transporter reads {key!r} as an image of the colour's (H, W) = {(rows, cols)}; "
                                  f"arena {spec.name!r} observes {key!r}: {spaces[key]!r}")
            height_key = key
            break
    if height_key == DEPTH_KEY:
        table_depth = float(np.max(np.asarray(spaces[DEPTH_KEY].high)))
        if not np.isfinite(table_depth):
            raise ConfigError(f"transporter reads the table's depth from the upper bound of {DEPTH_KEY!r}'s spec; "
                              f"arena {spec.name!r}'s is {spaces[DEPTH_KEY]!r}")
    fits = _frames(spec.action, rows, cols)
    if frame not in FRAMES:
        raise ConfigError(f"transporter: unknown action_frame {frame!r}; choose from {list(FRAMES)}")
    if not fits or (frame != "auto" and frame not in fits):
        wanted = {"auto": "", "pixels": " (action_frame: pixels)", "image_points": " (action_frame: image_points)"}
        raise ConfigError(f"transporter acts{wanted[frame]} with (pick_row, pick_col, place_row, place_col, place_yaw) "
                          f"in image pixels (rows 0..{rows - 1}, columns 0..{cols - 1}) and radians, or with one pick "
                          f"and one place as normalised image points (pick_u, pick_v, place_u, place_v) in [-1, 1]; "
                          f"arena {spec.name!r} acts with {spec.action!r} (an action tool such as rescale in front of "
                          f"the primitive changes it)")
    frame = fits[0] if frame == "auto" else frame
    if frame == "image_points" and rotations > 1:
        raise ConfigError(f"transporter: arena {spec.name!r} acts with image points, which have no yaw; set "
                          f"rotations: 1 (got {rotations})")
    return Layout(shape=(rows, cols), frame=frame, height_key=height_key, table_depth=table_depth)


def check_tool(tool_name: str, layout: Layout, frame: str) -> None:
    """With ``action_frame: auto``, a ``ConfigError`` unless an arena acting with image points has an action tool
    whose name says it takes pixels (``pixel_pick_and_place``): a [-1, 1]^4 action may be points of another frame
    (the cloth's ``pick_and_place`` takes normalised world x-y, y pointing up the image). ``action_frame:
    image_points`` skips the check."""
    if layout.frame == "image_points" and frame == "auto" and "pixel" not in tool_name:
        raise ConfigError(f"transporter: the arena's action tool {tool_name!r} may not take normalised image points; "
                          f"use one that does (e.g. action:pixel_pick_and_place(1)), or set action_frame: "
                          f"image_points if its (4,) action is (pick_u, pick_v, place_u, place_v)")
