"""Assembling-kits' pieces (Ravens' ``ravens/tasks/assembling_kits.py``): the 20 kitting shapes as unions of boxes,
the kit with its five slots, and each episode's shapes in the scene's boxes.

Ravens' kitting shapes are meshes (``kitting/00.obj`` to ``19.obj`` at Ravens' scale: letters and polygons 3.2 to
7.5 cm across and 2 cm high, origin at the centre of their outline). MJX collides no non-convex meshes, so each
shape here is a union of at most :data:`MAX_PARTS` upright boxes 2 cm high: exact for the rectilinear shapes
(square, rectangle, plus, T, L, E) and for the hexagon (three rectangles through its centre), a regular octagon
for the circle, a hexagonal ring for the ring, and for the others boxes fitted to the mesh's outline seen from
above (91% to 99% of it covered, at most 1.5% outside it: :data:`SHAPES`); every shape spans its mesh's outline
within 3 mm. A slot is a thin mark of its shape on the kit (dark grey on the brown kit, as Ravens' slot
templates), seen and never touched.

The scene holds :data:`OBJECTS` object bodies and one kit body whose boxes a task sets per episode (sizes,
positions and headings in the body's frame, :attr:`.physics.RavenPhysics.geom_quat`): each object's
:data:`MAX_PARTS` boxes take its shape's parts, a shape with fewer parts hides the rest as slivers inside its first
part; the kit's tiles stay, and each slot's :data:`MAX_PARTS` marks take the shape of its object.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.raven import poses
from jarena.arenas.raven.scene import Box, Shape, rgb

SHAPE_NAMES = ("letter R", "letter A", "triangle", "square", "plus", "letter T", "diamond", "pentagon",
               "rectangle", "flower", "star", "circle", "letter G", "letter V", "letter E", "letter L", "ring",
               "hexagon", "heart", "letter M")
"""The 20 kitting shapes, in Ravens' numbering (its ``kitting/NN.obj``)."""
SYMMETRY = tuple(float(s) for s in (
    2 * np.pi, 2 * np.pi, 2 * np.pi / 3, np.pi / 2, np.pi / 2, 2 * np.pi, np.pi, 2 * np.pi / 5, np.pi, np.pi / 2,
    2 * np.pi / 5, 0.0, 2 * np.pi, 2 * np.pi, 2 * np.pi, 2 * np.pi, 0.0, 2 * np.pi / 6, 2 * np.pi, 2 * np.pi))
"""Each shape's rotational symmetry about +z, radians (Ravens' list: 2 pi none, 0 any heading: circle and ring)."""
TRAIN_SHAPES = tuple(range(14))
TEST_SHAPES = tuple(range(14, 20))
"""The shapes training episodes draw from, and the unseen ones of eval and val episodes (Ravens' ``train_set`` and
``test_set``; Ravens draws from the test set in any mode but ``train``)."""

OBJECTS = 5
"""Objects (and slots) an episode (Ravens' ``n_objects``)."""
HEIGHT = 0.02
"""The objects' height, metres (Ravens' meshes, 20 units at a z scale of 0.001)."""
EXTENT = (0.08, 0.08, 0.02)
"""The extent an object is laid out with, metres (Ravens' ``size`` for ``get_random_pose``)."""
KIT_SIZE = (0.28, 0.2, 0.005)
"""The kit's full extents, metres (Ravens' ``kit.urdf``)."""
SLOT_OFFSETS = ((-0.09, 0.045), (0.0, 0.045), (0.09, 0.045), (-0.045, -0.045), (0.045, -0.045))
"""The slots' centres in the kit's frame, metres (Ravens' ``targ_pos``): three along +y, two along -y."""
MARK_HEIGHT = 0.001
"""A slot mark's thickness, metres: it stands on the kit's top (Ravens' slot templates stick out 0.9 mm)."""
KIT_RGB = (0.6118, 0.4588, 0.3725)
MARK_RGB = (0.2, 0.2, 0.2)
"""The kit's colour (brown) and its slot marks' (dark grey), Ravens'."""
COLOURS = tuple(rgb(name) for name in ("purple", "blue", "green", "yellow", "red"))
"""The objects' colours, in order (Ravens')."""
MAX_PARTS = 6
"""Boxes per shape at most."""
TILES = (4, 3)
"""The kit is drawn as 4 x 3 tiles of 7 x 6.7 cm, so that every box of the scene is small: the heightmap casts each
box's rays through a square the size of the largest."""

_MM = 0.001
SLIVER = 0.0005
"""The half extent (x and y), metres, of the slivers that stand for a shape's missing parts."""
SHAPES: tuple[tuple[tuple[float, float, float, float, float], ...], ...] = (
    # (centre x, centre y, extent x, extent y, heading in degrees), millimetres, in the mesh's frame
    ((-14.5, 0.0, 56.8, 11.8, 90.0), (0.1, 22.0, 19.0, 10.3, 168.4), (9.0, 12.0, 18.6, 11.2, 93.4),
     (0.8, 0.3, 21.5, 9.0, 17.8), (5.4, -13.1, 10.9, 31.9, 29.8)),  # 0 letter R
    ((-9.4, -0.2, 10.5, 58.4, 160.4), (9.3, -0.2, 58.3, 10.6, 109.4), (0.0, -7.2, 31.3, 10.2, 0.0)),  # 1 letter A
    ((-0.6, 21.2, 17.3, 42.5, 90.0), (-0.7, 6.2, 25.6, 26.7, 41.3), (-12.5, 1.8, 61.9, 5.8, 116.3),
     (12.2, 3.9, 8.3, 56.7, 153.6)),  # 2 triangle
    ((0.0, 0.0, 60.0, 60.0, 0.0),),  # 3 square
    ((0.0, 0.0, 60.0, 30.0, 0.0), (0.0, 0.0, 30.0, 60.0, 0.0)),  # 4 plus
    ((-9.0, 0.0, 42.0, 18.0, 0.0), (21.0, 0.0, 18.0, 60.0, 0.0)),  # 5 letter T
    ((0.0, 0.0, 38.2, 46.6, 39.0), (16.4, 10.8, 43.5, 9.2, 141.5), (-16.4, -10.8, 43.5, 9.2, 141.5)),  # 6 diamond
    ((-0.2, 6.1, 41.7, 36.0, 90.0), (3.1, 3.0, 33.9, 42.5, 108.3), (1.4, -0.9, 35.6, 40.5, 36.1),
     (-14.8, 6.0, 34.4, 18.2, 72.2)),  # 7 pentagon
    ((0.0, 0.0, 75.0, 45.0, 0.0),),  # 8 rectangle
    ((0.0, 0.0, 54.0, 22.0, 0.0), (0.0, 0.0, 22.0, 54.0, 0.0), (0.0, 0.0, 44.0, 44.0, 45.0)),  # 9 flower
    ((-3.6, -2.1, 28.4, 31.5, 71.6), (-5.9, 11.8, 8.9, 33.4, 130.1), (-7.5, 11.2, 33.4, 9.2, 177.6),
     (15.8, -1.5, 14.8, 8.4, 26.9), (-12.5, -12.7, 6.1, 27.3, 99.7), (-1.0, -17.6, 6.2, 22.0, 44.7)),  # 10 star
    tuple((0.0, 0.0, 58.0, 24.02, 45.0 * k) for k in range(4)),  # 11 circle: an octagon 5.8 cm across its flats
    ((-15.4, -5.8, 26.9, 11.1, 99.7), (-11.5, 15.4, 22.1, 10.6, 51.6), (7.7, 22.8, 10.2, 25.3, 84.2),
     (-1.1, -22.4, 10.2, 24.8, 79.1), (16.7, -11.7, 11.3, 30.5, 0.0), (11.4, -1.5, 21.5, 10.8, 179.3)),  # 12 letter G
    ((-8.6, 0.1, 11.0, 57.7, 17.8), (8.5, 0.1, 57.7, 11.0, 72.2)),  # 13 letter V
    ((-10.1, 0.0, 11.8, 56.8, 0.0), (5.9, 22.9, 20.2, 11.0, 0.0), (5.2, 1.15, 18.8, 11.1, 0.0),
     (5.9, -22.9, 20.2, 11.0, 0.0)),  # 14 letter E
    ((-21.0, 0.0, 18.0, 60.0, 0.0), (9.0, -21.0, 42.0, 18.0, 0.0)),  # 15 letter L
    tuple((20.0 * np.cos(np.pi * k / 3), 20.0 * np.sin(np.pi * k / 3), 16.0, 32.33, 60.0 * k)
          for k in range(6)),  # 16 ring: a hexagonal ring, 5.6 cm across its outer flats, 2.4 cm its inner ones
    ((0.0, 0.0, 52.0, 30.0, 0.0), (0.0, 0.0, 52.0, 30.0, 60.0), (0.0, 0.0, 52.0, 30.0, 120.0)),  # 17 hexagon
    ((-12.5, 5.7, 38.2, 19.0, 113.0), (12.5, 5.7, 38.2, 19.0, 67.0), (-3.6, -0.3, 30.6, 44.3, 42.7),
     (3.6, -0.3, 30.6, 44.3, 137.3)),  # 18 heart
    ((-21.2, 0.0, 11.2, 56.8, 0.0), (-8.7, -0.1, 10.8, 57.3, 18.3), (8.4, -0.2, 57.6, 10.2, 71.0),
     (21.0, 0.0, 11.8, 56.8, 0.0)),  # 19 letter M
)
"""Each shape's boxes seen from above (:data:`SHAPE_NAMES` order), in the frame of Ravens' mesh."""


def part_table() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every shape's :data:`MAX_PARTS` boxes: ``(centres (20, P, 2), half extents (20, P, 2), headings (20, P))``,
    metres and radians. A shape with fewer parts gets slivers (:data:`SLIVER`) at its first part's centre."""
    centres = np.zeros((len(SHAPES), MAX_PARTS, 2), np.float32)
    half = np.full((len(SHAPES), MAX_PARTS, 2), SLIVER, np.float32)
    yaw = np.zeros((len(SHAPES), MAX_PARTS), np.float32)
    for s, parts in enumerate(SHAPES):
        for k in range(MAX_PARTS):
            cx, cy, sx, sy, degrees = parts[k] if k < len(parts) else parts[0]
            centres[s, k] = (cx * _MM, cy * _MM)
            yaw[s, k] = np.deg2rad(degrees)
            if k < len(parts):
                half[s, k] = (sx * _MM / 2, sy * _MM / 2)
    return centres, half, yaw


def _tiles() -> tuple[Box, ...]:
    """The kit's tiles, seen and never touched, its origin at half its height."""
    size = np.asarray(KIT_SIZE) / np.asarray(TILES + (1,))
    return tuple(Box(tuple(float(v) for v in size), (float((i + 0.5) * size[0] - KIT_SIZE[0] / 2),
                                                       float((j + 0.5) * size[1] - KIT_SIZE[1] / 2), 0.0),
                     solid=False) for i in range(TILES[0]) for j in range(TILES[1]))


KIT_TILES = len(_tiles())
"""The kit body's first boxes, its tiles; each slot's :data:`MAX_PARTS` marks follow, slot by slot."""
MARK_Z = KIT_SIZE[2] / 2 + MARK_HEIGHT / 2
"""A mark's centre above the kit's origin, metres."""

KIT = Shape("kit", _tiles() + tuple(
    Box((0.06, 0.06, MARK_HEIGHT), (x, y, MARK_Z), solid=False, rgb=MARK_RGB)
    for x, y in SLOT_OFFSETS for _ in range(MAX_PARTS)),
    extent=KIT_SIZE, fixed=True, friction=1.0, rgb=KIT_RGB, resizable=True)
"""Ravens' ``kitting/kit.urdf``, a 28 x 20 x 0.5 cm brown board, with its slots' marks (set per episode), seen and
never touched: objects put on it rest on the table (5 mm lower than on Ravens' solid kit)."""

OBJECT = Shape("kitting object", (Box((0.06, 0.06, HEIGHT)),) + tuple(
    Box((0.001, 0.001, HEIGHT / 2)) for _ in range(MAX_PARTS - 1)),
    extent=EXTENT, mass=0.1, friction=1.0, resizable=True)
"""A kitting object's body (its shape set per episode): 0.1 kg (Ravens'), with the inertia of a 6 x 6 x 2 cm slab
(the square's) whatever its shape."""


@struct.dataclass
class Kitting:
    """What an episode of assembling-kits keeps beside the physics (``RavenPhysics.queue``).

    Attributes:
      shapes: int32 (5,): each object's shape (and its slot's, in order).
      targets: float32 (5, 4): the slots' poses ``(x, y, z, yaw)``, where an object of their shape rests in them.
    """

    shapes: jax.Array
    targets: jax.Array


def _is_part(half: jax.Array) -> jax.Array:
    """bool (...): which boxes of half extents (..., 2 or 3) are parts, not slivers."""
    return half[..., 0] > 2 * SLIVER


def object_boxes(shapes: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The boxes of objects of ``shapes`` (K,) in their frames: ``(centres (K, P, 3), half extents (K, P, 3),
    headings (K, P))``, 2 cm high (slivers 1 cm high, inside their first part)."""
    centres, half, yaw = (jnp.asarray(x)[shapes] for x in part_table())
    height = jnp.where(_is_part(half), HEIGHT / 2, HEIGHT / 4)  # a sliver floats inside its shape's first part
    return (jnp.concatenate([centres, jnp.zeros(centres.shape[:-1] + (1,))], -1),
            jnp.concatenate([half, height[..., None]], -1), yaw)


def slot_marks(shapes: jax.Array, slot_yaw: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The marks of slots of ``shapes`` (5,) turned by ``slot_yaw`` (5,) radians in the kit's frame: ``(centres
    (5 x P, 3), half extents (5 x P, 3), headings (5 x P,))`` in the kit's frame, slot by slot."""
    centres, half, yaw = object_boxes(shapes)
    turn = poses.yaw_quat(slot_yaw)[:, None, :]
    offsets = jnp.asarray(SLOT_OFFSETS, jnp.float32)
    centres = poses.rotate(turn, centres) + jnp.concatenate([offsets, jnp.full((OBJECTS, 1), MARK_Z)], -1)[:, None]
    half = half.at[..., 2].set(jnp.where(_is_part(half), MARK_HEIGHT / 2, MARK_HEIGHT / 4))
    return centres.reshape(-1, 3), half.reshape(-1, 3), (yaw + slot_yaw[:, None]).reshape(-1)
