"""Packing-boxes' pieces (Ravens' ``ravens/tasks/packing_boxes.py``): the container, the kd-split that cuts its
inside into boxes, and each box's points for the zone metric.

A container of random size (5-30 x 5-30 x 5 cm) stands open on the table; its inside, less a 1 cm rim, is cut
into boxes by Ravens' kd-tree: a part longer than twice :data:`MIN_OBJECT_DIM` along some axis is cut across one
such axis (drawn uniformly among them) at a point drawn uniformly that leaves 5 cm on either side, and the two
halves, :data:`MARGIN` apart, are cut in turn (the first before the second); a part that no axis allows to be cut
is a box. Boxes are 4.5 to 10 cm a side and 5 cm high (the height is never cut); a side the container is too
narrow to cut is the whole inside's, as narrow as 3 cm. Everything is in JAX with a fixed number of box slots
(:func:`kd_split`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.raven.scene import Box, Shape, rgb
from jarena.arenas.raven.scoring import POINT_SPACING

CONTAINER_SIZE = ((0.05, 0.3), (0.05, 0.3), (0.05, 0.05))
"""The container's range of full extents along x, y and z, metres (Ravens' ``get_random_size`` arguments)."""
MARGIN = 0.01
"""The gap between two halves of a cut, and the rim left inside the container's walls, metres (Ravens')."""
MIN_OBJECT_DIM = 0.05
"""A cut leaves at least this much on either side (less half the margin), metres (Ravens' ``min_object_dim``)."""
MAX_BOXES = 20
"""Box slots in the scene: the most boxes an episode can have here (Ravens' 20 actions can pack no more). Ravens'
rule can make up to 25; it made more than 20 once in 200,000 simulated episodes, where the split here stops
cutting."""
MAX_GEOM_PAIRS = 32
"""The pairs of boxes (box and box, box and wall piece) that go through collision detection at each physics step,
the nearest of 430 (:class:`.scene.PhysicsOptions`)."""
WALL = 0.002
"""The container's walls and floor, metres thick (Ravens' ``container-template.urdf``)."""
LARGEST_BOX = (0.1, 0.1, 0.05)
"""The largest box the split makes, metres: a part is cut while longer than 10 cm."""

_CONTAINER_RGB = (0.6118, 0.4588, 0.3725)
BOX_COLOURS = tuple(rgb(name) for name in ("blue", "red", "green", "orange", "yellow", "purple", "pink", "cyan",
                                           "gray"))
"""The boxes' colours, one drawn uniformly for each box: Ravens' palette without brown."""


PIECES = 3
"""The container's floor is :data:`PIECES` x :data:`PIECES` tiles and each wall :data:`PIECES` pieces in a row
(each at most 10 cm long), so that every box of the scene is small: the heightmap casts each box's rays through a
square the size of the largest, and MJX's broad phase bounds each box by a sphere."""


def _container_layout() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The container's boxes as multiples of its size: ``(centres, halves, thickness)``, each (P, 3), such that a
    box's centre is ``centres * size`` and its half extents ``halves * size + thickness``."""
    offsets = (np.arange(PIECES) - (PIECES - 1) / 2) / PIECES
    piece, wall = 1 / (2 * PIECES), WALL / 2
    centres, halves, thickness = [], [], []
    for i in offsets:  # the floor, centred on the container's bottom
        for j in offsets:
            centres.append((i, j, -0.5)), halves.append((piece, piece, 0.0)), thickness.append((0.0, 0.0, wall))
    for side in (-0.5, 0.5):  # the walls at -y and +y, centred on the container's edges
        for i in offsets:
            centres.append((i, side, 0.0)), halves.append((piece, 0.0, 0.5)), thickness.append((0.0, wall, 0.0))
    for side in (-0.5, 0.5):  # at -x and +x
        for j in offsets:
            centres.append((side, j, 0.0)), halves.append((0.0, piece, 0.5)), thickness.append((wall, 0.0, 0.0))
    return tuple(np.asarray(a, np.float32) for a in (centres, halves, thickness))


FLOOR_PIECES = PIECES * PIECES
"""The container's first boxes, its floor's tiles; the wall pieces follow."""


def container_parts(size) -> tuple[jax.Array, jax.Array]:
    """The container's boxes for full extents ``size`` (3,): ``(half extents (P, 3), centres (P, 3))`` in its frame
    (its origin at half its height), P = 21: the floor's tiles, then the walls' pieces at -y, +y, -x and +x. As
    Ravens' template: walls and floor :data:`WALL` thick, centred on the container's edges and bottom, the walls
    its full length and height."""
    centres, halves, thickness = _container_layout()
    size = jnp.asarray(size, jnp.float32)
    return halves * size + thickness, centres * size


_LARGEST = np.asarray([0.3, 0.3, 0.05], np.float32)
CONTAINER = Shape("container", tuple(
    Box(tuple(float(v) for v in 2 * (half * _LARGEST + thick)), tuple(float(v) for v in centre * _LARGEST),
        solid=k >= FLOOR_PIECES) for k, (centre, half, thick) in enumerate(zip(*_container_layout(), strict=True))),
    extent=(0.3, 0.3, 0.05), fixed=True, friction=0.3, rgb=_CONTAINER_RGB, resizable=True)
"""Ravens' ``container/container-template.urdf`` at its largest (an episode sets its size): an open box of 2 mm
walls, brown, fixed, in :data:`PIECES`. Its floor is only seen (boxes put in it rest on the table, 1 mm under its
top)."""

BOX_SLOT = Shape("box", (Box(LARGEST_BOX),), extent=LARGEST_BOX, mass=0.1, friction=1.0, rgb=rgb("gray"),
                 resizable=True)
"""Ravens' ``box/box-template.urdf`` at the largest size the split makes (an episode sets its size): 0.1 kg."""


@struct.dataclass
class Packing:
    """What an episode of packing keeps beside the physics (``RavenPhysics.queue``).

    Attributes:
      targets: float32 (K, 4): each box slot's place in the container ``(x, y, z, yaw)``, where the split put it
        (Ravens' ``true_poses``, the oracle's targets).
      size: float32 (3,): the container's full extents, metres.
    """

    targets: jax.Array
    size: jax.Array


def kd_split(key: jax.Array, inside: jax.Array, capacity: int = MAX_BOXES
             ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Ravens' kd-tree cut of a container's inside into boxes (module docstring), depth first.

    Args:
      key: PRNG key.
      inside: float32 (2,): the extents to cut along x and y, metres (the container's less the rim on each side).
      capacity: the most boxes; a part is cut only while the boxes it can make fit (Ravens cuts on).

    Returns:
      ``(centres, sizes, present)``: float32 (capacity, 2) the boxes' centres relative to the inside's centre and
      their extents (x, y), metres, in Ravens' order (the first half of every cut before the second), and bool
      (capacity,) the slots used (the first ones); unused slots are zeros.
    """
    inside = jnp.asarray(inside, jnp.float32)
    zeros = jnp.zeros((capacity, 2), jnp.float32)
    stack_lo, stack_hi = zeros.at[0].set(-inside / 2), zeros.at[0].set(inside / 2)
    carry = (stack_lo, stack_hi, jnp.ones((), jnp.int32), zeros, zeros, jnp.zeros((), jnp.int32))

    def visit(i, carry):  # pop the part on top of the stack: cut it (the first half on top), or keep it as a box
        stack_lo, stack_hi, top, box_lo, box_hi, count = carry
        busy = top > 0
        slot = jnp.maximum(top - 1, 0)
        lo, hi = stack_lo[slot], stack_hi[slot]
        size = hi - lo
        can = size > 2 * MIN_OBJECT_DIM
        key_axis, key_cut = jax.random.split(jax.random.fold_in(key, i))
        axis = jax.random.categorical(key_axis, jnp.where(can, 0.0, -jnp.inf))
        axis = jnp.where(jnp.any(can), axis, 0)
        cut = (jax.random.uniform(key_cut, (), jnp.float32) * (size[axis] - 2 * MIN_OBJECT_DIM) + lo[axis]
               + MIN_OBJECT_DIM)
        # after the cut the stack holds top - 1 parts and two halves, each at least one box
        split = busy & jnp.any(can) & (count + top + 1 <= capacity)
        keep = busy & ~split
        first_hi, second_lo = hi.at[axis].set(cut - MARGIN / 2), lo.at[axis].set(cut + MARGIN / 2)
        stack_lo = jnp.where(split, stack_lo.at[slot].set(second_lo).at[slot + 1].set(lo, mode="drop"), stack_lo)
        stack_hi = jnp.where(split, stack_hi.at[slot].set(hi).at[slot + 1].set(first_hi, mode="drop"), stack_hi)
        box_lo = jnp.where(keep, box_lo.at[count].set(lo, mode="drop"), box_lo)
        box_hi = jnp.where(keep, box_hi.at[count].set(hi, mode="drop"), box_hi)
        top = top + split.astype(jnp.int32) - keep.astype(jnp.int32)
        return stack_lo, stack_hi, top, box_lo, box_hi, count + keep.astype(jnp.int32)

    _, _, _, box_lo, box_hi, count = jax.lax.fori_loop(0, 2 * capacity - 1, visit, carry)
    present = jnp.arange(capacity) < count
    return (jnp.where(present[:, None], (box_lo + box_hi) / 2, 0.0),
            jnp.where(present[:, None], box_hi - box_lo, 0.0), present)


def points_grid(sizes: jax.Array, largest=LARGEST_BOX) -> tuple[jax.Array, jax.Array]:
    """Ravens' points of boxes of full extents ``sizes`` (K, 3): a grid every :data:`POINT_SPACING` from
    ``-size / 2`` on each axis, short of ``size / 2``, padded to the largest box's: ``(points (K, P, 3), valid
    (K, P))``, P = 75 for 10 x 10 x 5 cm."""
    counts = [int(np.ceil(s / POINT_SPACING - 1e-6)) for s in largest]
    steps = np.stack(np.meshgrid(*(np.arange(c) for c in counts), indexing="ij"), -1).reshape(-1, 3)
    steps = jnp.asarray(steps, jnp.float32) * POINT_SPACING  # (P, 3)
    sizes = jnp.asarray(sizes, jnp.float32)
    points = steps[None] - sizes[:, None, :] / 2
    valid = jnp.all(steps[None] < sizes[:, None, :], axis=-1)
    return jnp.where(valid[..., None], points, 0.0), valid
