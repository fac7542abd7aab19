"""Ravens' tasks: each names its objects, lays out an episode and sets its goal (``ravens/tasks/*.py``).

A scene holds every object a task may use; the objects an episode leaves out stay parked off the table (their
pose at ``init``), and the goal tells them apart by where they are (:func:`on_table`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.raven import kits, layout, packing, poses
from jarena.arenas.raven import scene as shapes
from jarena.arenas.raven.heightmap import BOUNDS
from jarena.arenas.raven.physics import RavenPhysics, object_poses, place_movable, place_objects
from jarena.arenas.raven.scene import BLOCK, Item, rgb
from jarena.arenas.raven.scoring import POINT_SPACING, Goal, Zone, planar_poses


@dataclasses.dataclass(frozen=True)
class RavenTask:
    """A tabletop task.

    Attributes:
      name: Ravens' name (``block-insertion``).
      items: the scene's objects, movable ones first.
      max_steps: actions per episode (Ravens' ``max_steps``).
      pos_eps: metres within which an object matches its target (Ravens' ``pos_eps``).
      initialize: ``(key, physics) -> physics``: the episode's layout.
      goal: ``(physics) -> Goal`` at the episode's start.
      after_action: ``(physics) -> (physics, over)`` once per pick-and-place, before its last control step (after
        the place): what the task changes between actions (palletizing spawns the next box), and whether that
        ends the episode (bool ()); ``None``: nothing.
      pairs: explicit contact pairs of items (names), beside those their collision bits allow.
      max_geom_pairs: ``None``, or the pairs of boxes that go through collision detection at each physics step,
        the nearest (:class:`.scene.PhysicsOptions`).
      by_split: whether the layout differs between splits: ``initialize`` then takes a third argument, bool (),
        whether the episode is held out (an eval or val episode, :mod:`.splits`).
    """

    name: str
    items: tuple[Item, ...]
    max_steps: int
    pos_eps: float
    initialize: Callable[[jax.Array, RavenPhysics], RavenPhysics]
    goal: Callable[[RavenPhysics], Goal]
    after_action: Callable[[RavenPhysics], tuple[RavenPhysics, jax.Array]] | None = None
    pairs: tuple[tuple[str, str], ...] = ()
    max_geom_pairs: int | None = None
    by_split: bool = False


def on_table(planar: jax.Array) -> jax.Array:
    """bool (...): which objects, of planar poses (..., 4), are in the workspace (the others are parked)."""
    return (planar[..., 0] >= BOUNDS[0][0]) & (planar[..., 0] <= BOUNDS[0][1])


def place_present(physics: RavenPhysics, pos: jax.Array, quat: jax.Array, present: jax.Array) -> RavenPhysics:
    """``physics`` with the ``present`` (bool (N,)) objects at ``pos``, ``quat`` (scene order) and the others left
    where they are (parked)."""
    parked_pos, parked_quat = object_poses(physics)
    return place_objects(physics, jnp.where(present[:, None], pos, parked_pos),
                         jnp.where(present[:, None], quat, parked_quat))


def _in_frame(pose: jax.Array, offsets) -> jax.Array:
    """float32 (K, 2): points ``offsets`` (K, 2) of a frame at planar ``pose`` (x, y, ..., yaw), in the world."""
    offsets = jnp.asarray(offsets, jnp.float32)
    cos, sin = jnp.cos(pose[3]), jnp.sin(pose[3])
    return pose[:2] + jnp.stack([cos * offsets[:, 0] - sin * offsets[:, 1], sin * offsets[:, 0] + cos * offsets[:, 1]],
                                -1)


def block_insertion() -> RavenTask:
    """Ravens' ``block-insertion``: put the L-shaped block into the L-shaped fixture, in its pose (the L has no
    symmetry: 2 pi). Both are placed at random in free space, the block first; 3 actions."""
    items = (Item("ell", shapes.ELL), Item("fixture", shapes.FIXTURE))

    def initialize(key, physics):
        pos, quat, _, _ = layout.place_in_turn(key, (shapes.ELL, shapes.FIXTURE))
        return place_objects(physics, pos, quat)

    def goal(physics):
        fixture = planar_poses(physics)[1]
        return Goal(objects=jnp.asarray([0], jnp.int32), present=jnp.ones((1,), bool),
                    symmetry=jnp.asarray([2 * np.pi], jnp.float32), targets=fixture[None],
                    target_present=jnp.ones((1,), bool), matches=jnp.ones((1, 1), bool))

    return RavenTask("block-insertion", items, max_steps=3, pos_eps=0.01, initialize=initialize, goal=goal)


DISTRACTORS = 10
"""place-red-in-green's distractors (blocks or bowls, each a coin toss)."""


def place_red_in_green() -> RavenTask:
    """Ravens' ``place-red-in-green``: put each red block in a green bowl (any bowl, any heading, within 5 cm of its
    centre; blocks matched to bowls without replacement by the oracle, each block scored on its own).

    An episode has 1-3 green bowls (fixed), 1 to that many red blocks and 10 distractors, each a block (not red)
    or a bowl (not green) with even odds, coloured in turn from Ravens' palette; all placed in turn in free space:
    bowls, blocks, distractors (one that finds no room is left out, where Ravens draws another). 10 actions.
    Distractors collide with the table and the red blocks, not with each other (a distractor put on another sinks
    into it), which keeps the contacts few.
    """
    not_red = [rgb(c) for c in shapes.COLORS if c != "red"]
    not_green = [rgb(c) for c in shapes.COLORS if c != "green"]
    red, key_bits, distractor_bits = rgb("red"), 3, (1, 2)
    reds = tuple(Item(f"red{i}", BLOCK, red, key_bits, key_bits) for i in range(3))
    blocks = tuple(Item(f"block{k}", BLOCK, not_red[k % len(not_red)], *distractor_bits) for k in range(DISTRACTORS))
    bowls = tuple(Item(f"bowl{k}", shapes.BOWL, not_green[k % len(not_green)], *distractor_bits)
                  for k in range(DISTRACTORS))
    greens = tuple(Item(f"green{i}", shapes.BOWL_FIXED, rgb("green")) for i in range(3))
    items = reds + tuple(x for pair in zip(blocks, bowls, strict=True) for x in pair) + greens
    # Ravens' order of placing: the green bowls, the red blocks, then the distractors (in scene order)
    order = np.concatenate([np.arange(len(items) - 3, len(items)), np.arange(len(items) - 3)])

    def initialize(key, physics):
        key_bowls, key_blocks, key_kinds, key_layout = jax.random.split(key, 4)
        bowls_count = jax.random.randint(key_bowls, (), 1, 4)
        blocks_count = jax.random.randint(key_blocks, (), 1, bowls_count + 1)
        is_block = jax.random.uniform(key_kinds, (DISTRACTORS,)) > 0.5
        present = jnp.concatenate([jnp.arange(3) < blocks_count,
                                   jnp.stack([is_block, ~is_block], -1).reshape(-1), jnp.arange(3) < bowls_count])
        pos, quat, found, _ = layout.place_in_turn(key_layout, tuple(items[i].shape for i in order),
                                                   present=present[order])
        back = np.argsort(order)
        return place_present(physics, pos[back], quat[back], found[back])

    def goal(physics):
        planar = planar_poses(physics)
        return Goal(objects=jnp.arange(3, dtype=jnp.int32), present=on_table(planar[:3]),
                    symmetry=jnp.zeros(3, jnp.float32), targets=planar[-3:], target_present=on_table(planar[-3:]),
                    matches=jnp.ones((3, 3), bool))

    return RavenTask("place-red-in-green", items, max_steps=10, pos_eps=0.05, initialize=initialize, goal=goal)


def corner_marks(box_size: jax.Array) -> jax.Array:
    """float32 (2, 3): the centres of the corner's two marks for a box of full extents ``box_size`` (3,) (Ravens'
    ``DIMX``, ``DIMY``): along the box's +y side and its +x side, 2.5 mm outside it, reaching its +x +y corner."""
    x, y = box_size[0] / 2, box_size[1] / 2
    zero = jnp.zeros_like(x)
    return jnp.stack([jnp.stack([x - 0.025 + 0.0025, y + 0.0025, zero]),
                      jnp.stack([x + 0.0025, y - 0.025 + 0.0025, zero])])


def corner_targets(corner: jax.Array, box_size: jax.Array) -> jax.Array:
    """float32 (4, 4): the box's target poses ``(x, y, z, yaw)`` for a corner at planar ``corner`` (4,): Ravens'
    four, the corner's pose, turned half a turn, and two poses turned a quarter and three quarters of a turn
    with the box's centre moved so that its other sides meet the marks."""
    x, y = box_size[0] / 2, box_size[1] / 2
    moved = _in_frame(corner, [[x - y, y - x]])[0]
    xy = jnp.stack([corner[:2], corner[:2], moved, moved])
    yaw = corner[3] + jnp.asarray([0.0, np.pi, np.pi / 2, 3 * np.pi / 2])
    return jnp.concatenate([xy, jnp.full((4, 1), box_size[2] / 2), poses.wrap_angle(yaw)[:, None]], -1)


def align_box_corner() -> RavenTask:
    """Ravens' ``align-box-corner``: push a box of random size into the corner drawn on the table.

    The box is 5-15 x 5-15 x 1-6 cm (uniform), a random shade of brown; the corner (two marks, only seen) is laid
    out first, in free space for the box's footprint, then the box. Four target poses (:func:`corner_targets`),
    heading counted in full (2 pi), 1 cm; 3 actions.
    """
    items = (Item("box", shapes.BOX), Item("corner", shapes.CORNER))
    marks_half = jnp.asarray([[0.0275, 0.0025, 0.0005], [0.0025, 0.0275, 0.0005]], jnp.float32)

    def initialize(key, physics):
        key_size, key_shade, key_corner, key_box = jax.random.split(key, 4)
        size = jax.random.uniform(key_size, (3,), jnp.float32, jnp.asarray([0.05, 0.05, 0.01]),
                                  jnp.asarray([0.15, 0.15, 0.06]))
        shade = jax.random.uniform(key_shade, (), jnp.float32, 0.5, 1.5)
        marks = corner_marks(size)
        corner_pos, corner_quat, _ = layout.random_pose(key_corner, layout.border(), size.at[2].set(0.0))
        taken = layout.border() | layout.footprint((marks, marks_half, jnp.zeros(2)), corner_pos, corner_quat)
        box_pos, box_quat, _ = layout.random_pose(key_box, taken, size)
        brown = jnp.clip(shade * jnp.asarray(rgb("brown")), 0.0, 1.0)
        physics = physics.replace(geom_size=physics.geom_size.at[0].set(size / 2),
                                  geom_pos=physics.geom_pos.at[1:3].set(marks),
                                  geom_rgb=physics.geom_rgb.at[0].set(brown))
        return place_objects(physics, jnp.stack([box_pos, corner_pos]), jnp.stack([box_quat, corner_quat]))

    def goal(physics):
        corner = planar_poses(physics)[1]
        return Goal(objects=jnp.asarray([0], jnp.int32), present=jnp.ones((1,), bool),
                    symmetry=jnp.asarray([2 * np.pi], jnp.float32),
                    targets=corner_targets(corner, 2 * physics.geom_size[0]), target_present=jnp.ones((4,), bool),
                    matches=jnp.ones((1, 4), bool))

    return RavenTask("align-box-corner", items, max_steps=3, pos_eps=0.01, initialize=initialize, goal=goal)


PYRAMID = ((0.0, -0.05, 0.03), (0.0, 0.0, 0.03), (0.0, 0.05, 0.03), (0.0, -0.025, 0.08), (0.0, 0.025, 0.08),
           (0.0, 0.0, 0.13))
"""The pyramid's places in the stand's frame, metres (Ravens'): three at the bottom, two above, one on top."""


def stack_block_pyramid() -> RavenTask:
    """Ravens' ``stack-block-pyramid``: stack six blocks in a pyramid on the stand, row by row.

    The stand (three 5 cm squares in a row) is laid out first, then the blocks (purple, blue, green, yellow, orange,
    red). Three stages: the bottom row (any of the first three blocks on any of its places, 1/2), the middle row
    (yellow and orange, 1/3), the top (red, 1/6); blocks count a quarter turn as none (pi / 2); 12 actions.
    """
    colours = ("purple", "blue", "green", "yellow", "orange", "red")
    items = tuple(Item(c, BLOCK, rgb(c)) for c in colours) + (Item("stand", shapes.PYRAMID_BASE),)
    rows = np.asarray([0, 0, 0, 1, 1, 2])

    def initialize(key, physics):
        pos, quat, _, _ = layout.place_in_turn(key, (shapes.PYRAMID_BASE,) + (BLOCK,) * 6)
        return place_objects(physics, jnp.concatenate([pos[1:], pos[:1]]), jnp.concatenate([quat[1:], quat[:1]]))

    def goal(physics):
        stand = planar_poses(physics)[6]
        places = jnp.asarray(PYRAMID, jnp.float32)
        targets = jnp.concatenate([_in_frame(stand, places[:, :2]), stand[2] + places[:, 2:],
                                   jnp.full((6, 1), stand[3])], -1)
        return Goal(objects=jnp.arange(6, dtype=jnp.int32), present=jnp.ones(6, bool),
                    symmetry=jnp.full(6, np.pi / 2, jnp.float32), targets=targets, target_present=jnp.ones(6, bool),
                    matches=jnp.asarray(rows[:, None] == rows[None, :]), stage=jnp.asarray(rows, jnp.int32),
                    weights=jnp.asarray([1 / 2, 1 / 3, 1 / 6], jnp.float32))

    return RavenTask("stack-block-pyramid", items, max_steps=12, pos_eps=0.01, initialize=initialize, goal=goal)


def hanoi_moves(disks: int = 3, source: int = 0, target: int = 2, spare: int = 1) -> list[tuple[int, int, int]]:
    """The moves ``(disk, from rod, to rod)`` that take ``disks`` disks (0 the smallest) from ``source`` to
    ``target``: Ravens' order, 7 moves for 3 disks."""
    if disks == 0:
        return []
    top = disks - 1
    return (hanoi_moves(top, source, spare, target) + [(top, source, target)]
            + hanoi_moves(top, spare, target, source))


RODS = (-0.12, 0.0, 0.12)
"""The rods along the stand's y axis, metres."""


def towers_of_hanoi() -> RavenTask:
    """Ravens' ``towers-of-hanoi``: move the three disks from the first rod to the third, one at a time, never a
    larger on a smaller.

    The stand is laid out in free space; the disks start stacked on its first rod, smallest on top. Seven stages of
    1/7, one per move of :func:`hanoi_moves`: the disk of the move within 1 cm of the rod's centre, any heading
    (0); 14 actions. Nothing stops a larger disk going on a smaller one, but the goal's order does not credit it.
    """
    items = tuple(Item(f"disk{i}", shapes.disk(i)) for i in range(3)) + (Item("stand", shapes.HANOI_STAND),)
    moves = hanoi_moves()

    def initialize(key, physics):
        pos, quat, _ = layout.random_pose(key, layout.border(), shapes.HANOI_STAND.extent)
        stand = jnp.concatenate([pos, poses.yaw_of(quat)[None]])
        rod = _in_frame(stand, [[0.0, RODS[0]]])[0]
        heights = 0.01 + 0.005 + 0.01 * jnp.asarray([2.0, 1.0, 0.0])  # the smallest on top
        disks = jnp.concatenate([jnp.broadcast_to(rod, (3, 2)), heights[:, None]], -1)
        return place_objects(physics, jnp.concatenate([disks, pos[None]]), jnp.broadcast_to(quat, (4, 4)))

    def goal(physics):
        stand = planar_poses(physics)[3]
        rods = _in_frame(stand, [[0.0, RODS[to]] for _, _, to in moves])
        targets = jnp.concatenate([rods, jnp.full((len(moves), 1), stand[2] + 0.03), jnp.zeros((len(moves), 1))], -1)
        count = len(moves)
        return Goal(objects=jnp.asarray([d for d, _, _ in moves], jnp.int32), present=jnp.ones(count, bool),
                    symmetry=jnp.zeros(count, jnp.float32), targets=targets, target_present=jnp.ones(count, bool),
                    matches=jnp.eye(count, dtype=bool), stage=jnp.arange(count, dtype=jnp.int32),
                    weights=jnp.full(count, 1 / count, jnp.float32))

    return RavenTask("towers-of-hanoi", items, max_steps=14, pos_eps=0.01, initialize=initialize, goal=goal)


PALLET_POSE = (0.5, 0.25, 0.02, 0.0)
"""The pallet's (and its zone's) pose ``(x, y, z, yaw)``, metres and radians (Ravens')."""
PALLET_ZONE = (0.3, 0.25)
"""The zone's extents along the pallet's x and y, metres (Ravens' ``zone_size``, whose height it does not use)."""
STACK_SIZE = (0.19, 0.19, 0.19)
STACK_DIM = (2, 3, 3)
STACK_MARGIN = 0.01
"""The stack of boxes on the pallet (Ravens'): its extents (metres), boxes along x, y and z before the first
layer's transposition, and the gap between neighbours (metres)."""
SPAWN_XY = (0.5, -0.25)
"""Where each box comes in, metres (Ravens' spawn point)."""


def stack_places() -> tuple[np.ndarray, np.ndarray]:
    """The stack's boxes in Ravens' order: ``(centres, sizes)``, float64 (18, 3) each, centres in the pallet's
    frame, full extents, metres. Layer by layer from the bottom; each layer first transposes the grid and the box
    (its x and y counts and extents swapped), then runs over y, then x."""
    stack, margin = np.asarray(STACK_SIZE, np.float64), STACK_MARGIN
    dim = np.asarray(STACK_DIM, np.int64)
    size = (stack - (dim - 1) * margin) / dim
    centres, sizes = [], []
    for z in range(int(dim[2])):
        dim[[0, 1]], size[[0, 1]] = dim[[1, 0]], size[[1, 0]]
        for y in range(int(dim[1])):
            for x in range(int(dim[0])):
                centre = (np.asarray([x, y, z]) + 0.5) * size
                centre += np.asarray([x * margin - stack[0] / 2, y * margin - stack[1] / 2, z * margin + 0.03])
                centres.append(centre)
                sizes.append(size.copy())
    return np.asarray(centres), np.asarray(sizes)


def box_points(size) -> np.ndarray:
    """float32 (P, 3): Ravens' points of a box of full extents ``size`` (3,): a grid every :data:`POINT_SPACING`
    from ``-size / 2`` on each axis, short of ``size / 2``."""
    axes = [np.arange(-s / 2, s / 2, POINT_SPACING) for s in size]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3).astype(np.float32)


@struct.dataclass
class SpawnQueue:
    """The boxes still to come in an episode of palletizing (``RavenPhysics.queue``).

    Attributes:
      order: int32 (K,): the boxes (scene indices) in the order they come in.
      yaw: float32 (K,): the heading each comes in with, radians.
      count: int32 (): how many have come in.
    """

    order: jax.Array
    yaw: jax.Array
    count: jax.Array


def spawn_order(key: jax.Array, layers: int, per_layer: int) -> jax.Array:
    """int32 (layers x per_layer,): the order boxes come in, the reverse of taking the full stack apart from the
    top (Ravens' time-reversed depalletizing): layer by layer from the bottom, each layer's boxes (numbered
    layer by layer) in a random order."""
    keys = jax.random.split(key, layers)
    return jnp.concatenate([jax.random.permutation(keys[z], per_layer) + z * per_layer
                            for z in range(layers)]).astype(jnp.int32)


def in_workspace(planar: jax.Array) -> jax.Array:
    """bool (...): which boxes, of planar poses (..., 4), are in the workspace where boxes come in: y in [-0.5, 0]
    metres (Ravens' test; boxes on the pallet's side have y > 0, parked ones y = 2)."""
    return (planar[..., 1] >= BOUNDS[1][0]) & (planar[..., 1] <= 0.0)


def palletizing_boxes() -> RavenTask:
    """Ravens' ``palletizing-boxes``: stack 18 boxes on the pallet, one at a time, as they come in.

    The stack (:func:`stack_places`) is 2 x 3 x 3 boxes of 5.7 x 9 x 5.7 cm, 1 cm apart, each layer turned a
    quarter turn from the one below, 19 cm a side. An episode starts with the pallet in its fixed place and one
    box in the workspace; the others are parked off the table, apart. Whenever the workspace is empty (every box
    on the pallet side, y > 0, or parked; checked once per action, once the box is placed and the cup has risen:
    :attr:`RavenTask.after_action`), the next box comes in at :data:`SPAWN_XY`, at rest on the table with a random
    heading, in the reverse of an order that takes the full stack apart from the top (:func:`spawn_order`; the
    order and headings are drawn at reset and kept in ``RavenPhysics.queue``). Boxes are brown of a random shade.
    The goal is one zone (Ravens' ``zone`` metric): the share of the 18 boxes' points over the pallet's 30 x 25 cm
    (1/18 a box); the targets where the oracle puts each box are its place in the stack (Ravens' targets, which
    the score does not use). As in Ravens, the episode ends after the first action that follows the last box's
    coming in; 30 actions.

    Boxes collide with the table and the pallet, and through explicit pairs each with its neighbours in the stack:
    the boxes of its layer next to its place (side by side or corner to corner, 1 cm apart) and those of the
    layers above and below whose places overlap its own, seen from above (65 pairs of the 153); not with boxes
    farther away in the stack.
    """
    centres, sizes = stack_places()
    count, per_layer = len(centres), STACK_DIM[0] * STACK_DIM[1]
    layers = count // per_layer
    layer = np.arange(count) // per_layer
    items = tuple(Item(f"box{i}", shapes.box(tuple(sizes[i])), contype=1, conaffinity=0) for i in range(count)) + (
        Item("pallet", shapes.PALLET),)
    pallet = np.asarray(PALLET_POSE, np.float32)
    cos, sin = np.cos(pallet[3]), np.sin(pallet[3])
    targets = np.concatenate([pallet[:2] + centres[:, :2] @ np.asarray([[cos, sin], [-sin, cos]]),
                              pallet[2] + centres[:, 2:], np.full((count, 1), pallet[3])], -1).astype(np.float32)
    # pairs: a box and the one above it where their places overlap seen from above, and neighbours in a layer
    # (side by side or corner to corner, their places 1 cm apart)
    gap = np.abs(centres[:, None, :2] - centres[None, :, :2]) - (sizes[:, None, :2] + sizes[None, :, :2]) / 2
    above = np.all(gap < 0, -1) & (layer[None, :] == layer[:, None] + 1)
    beside = np.all(gap < 2 * STACK_MARGIN, -1) & (layer[None, :] == layer[:, None])
    beside &= np.arange(count)[None, :] > np.arange(count)[:, None]
    pairs = tuple((f"box{i}", f"box{j}") for i, j in zip(*np.nonzero(above | beside), strict=True))
    points = [box_points(size) for size in sizes]
    most = max(len(p) for p in points)
    valid = np.asarray([np.arange(most) < len(p) for p in points])
    points = np.stack([np.concatenate([p, np.zeros((most - len(p), 3), np.float32)]) for p in points])
    half_height = jnp.asarray(sizes[:, 2] / 2, jnp.float32)
    brown = jnp.asarray(rgb("brown"), jnp.float32)

    def spawn(physics):
        queue = physics.queue
        over = queue.count >= count
        empty = ~jnp.any(in_workspace(planar_poses(physics)[:count]))
        come = empty & ~over
        box = queue.order[jnp.minimum(queue.count, count - 1)]
        pos = jnp.concatenate([jnp.asarray(SPAWN_XY, jnp.float32), half_height[box][None]])
        slot = jnp.asarray(physics.scene.movable_slot)[box]
        physics = place_movable(physics, slot, pos, poses.yaw_quat(queue.yaw[jnp.minimum(queue.count, count - 1)]),
                                come)
        return physics.replace(queue=queue.replace(count=queue.count + come.astype(jnp.int32))), over

    def initialize(key, physics):
        key_order, key_yaw, key_shade = jax.random.split(key, 3)
        shade = jax.random.uniform(key_shade, (count,), jnp.float32, 0.5, 1.5)
        box_of_geom = jnp.asarray(physics.scene.geom_object)
        colours = jnp.clip(shade[jnp.minimum(box_of_geom, count - 1), None] * brown, 0.0, 1.0)
        physics = physics.replace(geom_rgb=jnp.where((box_of_geom < count)[:, None], colours, physics.geom_rgb))
        pos, quat = object_poses(physics)
        pos = pos.at[count].set(pallet[:3])
        quat = quat.at[count].set(poses.yaw_quat(pallet[3]))
        physics = place_present(physics, pos, quat, jnp.arange(count + 1) == count)
        queue = SpawnQueue(order=spawn_order(key_order, layers, per_layer),
                           yaw=jax.random.uniform(key_yaw, (count,), jnp.float32, 0.0, 2 * np.pi),
                           count=jnp.zeros((), jnp.int32))
        physics, _ = spawn(physics.replace(queue=queue))
        return physics

    def goal(physics):
        zone = Zone(pose=jnp.asarray(pallet), size=jnp.asarray(PALLET_ZONE, jnp.float32),
                    points=jnp.asarray(points), valid=jnp.asarray(valid))
        return Goal(objects=jnp.arange(count, dtype=jnp.int32), present=jnp.ones(count, bool),
                    symmetry=jnp.zeros(count, jnp.float32), targets=jnp.asarray(targets),
                    target_present=jnp.ones(count, bool), matches=jnp.eye(count, dtype=bool), zone=zone)

    return RavenTask("palletizing-boxes", items, max_steps=30, pos_eps=0.01, initialize=initialize, goal=goal,
                     after_action=spawn, pairs=pairs)


def packing_boxes() -> RavenTask:
    """Ravens' ``packing-boxes``: put every box into the open container, which they fill, 1 cm apart, when packed
    as they were cut.

    The container (:mod:`.packing`) is 5-30 x 5-30 x 5 cm (uniform), laid out first in free space with a random
    heading; its inside less a 1 cm rim is cut into boxes by Ravens' kd-split (:func:`.packing.kd_split`), each
    box 5 cm high and of one of Ravens' colours but brown (drawn for each); then each box in turn (Ravens'
    order) goes to a random pose in the free space left by the container and the boxes before it (one that finds
    none starts in its place in the container). The goal is one zone (Ravens' ``zone`` metric): the share of all
    the boxes' points (a 2 cm grid over each box) inside the container's outer rectangle; the targets where the
    oracle puts each box are its place in the container as cut (Ravens' targets, which the score does not use;
    any heading matches, 1 cm); 20 actions.

    Where MJX makes it differ from Ravens: the scene has :data:`.packing.MAX_BOXES` box slots, each resized per
    episode (with the mass and inertia of the largest box); the slots an episode does not use stay parked off the
    table, apart (Ravens creates as many boxes as the split makes), and the split stops cutting once more boxes
    would not fit (Ravens' rule made more than 20 once in 200,000 simulated episodes). The container's floor is
    only seen (a box in it rests on the table, 1 mm lower). Boxes collide with the table, the container's walls
    and each other, but only the :data:`.packing.MAX_GEOM_PAIRS` nearest pairs of boxes go through collision
    detection at each physics step (MJX's broad phase).
    """
    count = packing.MAX_BOXES
    items = tuple(Item(f"box{i}", packing.BOX_SLOT) for i in range(count)) + (
        Item("container", packing.CONTAINER),)
    colours = jnp.asarray(packing.BOX_COLOURS, jnp.float32)
    size_low, size_high = (jnp.asarray(bound, jnp.float32) for bound in np.asarray(packing.CONTAINER_SIZE).T)

    def geoms(scene):
        """The box slots' geoms (one each, slot order) and the container's (floor, walls)."""
        return np.flatnonzero(scene.geom_object < count), np.flatnonzero(scene.geom_object == count)

    def initialize(key, physics):
        box_geoms, container_geoms = geoms(physics.scene)
        key_size, key_container, key_split, key_boxes, key_colour = jax.random.split(key, 5)
        size = jax.random.uniform(key_size, (3,), jnp.float32, size_low, size_high)
        pos, quat, _ = layout.random_pose(key_container, layout.border(), size)
        half, centres = packing.container_parts(size)
        xy, sizes, present = packing.kd_split(key_split, size[:2] - 2 * packing.MARGIN, count)
        extents = jnp.concatenate([sizes, jnp.full((count, 1), size[2])], -1)
        # Ravens' targets: the boxes where the split puts them, their centres at the container's mid-height
        inside = jnp.concatenate([xy, jnp.full((count, 1), size[2] / 2)], -1)
        target_pos = pos + poses.rotate(quat, inside)
        targets = jnp.concatenate([target_pos, jnp.broadcast_to(poses.yaw_of(quat), (count, 1))], -1)
        taken = layout.border() | layout.footprint((centres, half, jnp.zeros(len(centres))), pos, quat)

        def spawn(taken, slot):
            index, extent, here = slot
            box_pos, box_quat, found = layout.random_pose(jax.random.fold_in(key_boxes, index), taken, extent)
            found = found & here
            covered = layout.footprint((jnp.zeros((1, 3)), extent[None] / 2, jnp.zeros(1)), box_pos, box_quat)
            return taken | (covered & found), (box_pos, box_quat, found)

        _, (box_pos, box_quat, found) = jax.lax.scan(spawn, taken, (jnp.arange(count), extents, present))
        rest = target_pos.at[:, 2].set(size[2] / 2)
        box_pos = jnp.where(found[:, None], box_pos, rest)
        box_quat = jnp.where(found[:, None], box_quat, quat)
        shade = colours[jax.random.randint(key_colour, (count,), 0, colours.shape[0])]
        physics = physics.replace(
            geom_size=physics.geom_size.at[box_geoms].set(
                jnp.where(present[:, None], extents / 2, physics.geom_size[box_geoms])).at[container_geoms].set(half),
            geom_pos=physics.geom_pos.at[container_geoms].set(centres),
            geom_rgb=physics.geom_rgb.at[box_geoms].set(shade),
            queue=packing.Packing(targets=targets, size=size))
        return place_present(physics, jnp.concatenate([box_pos, pos[None]]),
                             jnp.concatenate([box_quat, quat[None]]), jnp.append(present, True))

    def goal(physics):
        box_geoms, _ = geoms(physics.scene)
        planar = planar_poses(physics)
        present = on_table(planar[:count])
        points, valid = packing.points_grid(2 * physics.geom_size[box_geoms])
        zone = Zone(pose=planar[count], size=physics.queue.size[:2], points=points, valid=valid)
        return Goal(objects=jnp.arange(count, dtype=jnp.int32), present=present,
                    symmetry=jnp.zeros(count, jnp.float32), targets=physics.queue.targets, target_present=present,
                    matches=jnp.eye(count, dtype=bool), zone=zone)

    return RavenTask("packing-boxes", items, max_steps=20, pos_eps=0.01, initialize=initialize, goal=goal,
                     max_geom_pairs=packing.MAX_GEOM_PAIRS)


KITS_MAX_GEOM_PAIRS = 16
"""assembling-kits' pairs of boxes of different objects that go through collision detection at each physics step,
the nearest of 360 (:class:`.scene.PhysicsOptions`)."""


def assembling_kits() -> RavenTask:
    """Ravens' ``assembling-kits``: put each of five objects into the slot of its shape on the kit.

    The kit (:data:`.kits.KIT`, 28 x 20 cm) is laid out first in free space with a random heading; its five
    slots sit at Ravens' offsets (:data:`.kits.SLOT_OFFSETS`), each with a heading drawn uniformly in [0, 2 pi)
    (as Ravens', a heading in the world, not the kit's frame). The five shapes are drawn uniformly with
    replacement from Ravens' training shapes 0-13 in a training episode and from the unseen shapes 14-19 in an eval
    or val episode (Ravens' test set, which it uses in any mode but ``train``); slot ``i`` takes shape ``i``.
    Then object ``i`` (purple, blue, green, yellow, red) goes to a random pose in the free space left by the kit
    and the objects before it, at rest on the table (one that finds none keeps the pose drawn). The goal is one
    stage: each object in any slot of its shape (Ravens' ``matches``) within 1 cm and 15 degrees modulo its
    shape's symmetry (:data:`.kits.SYMMETRY`), 1/5 an object; 10 actions.

    Where MJX makes it differ from Ravens (:mod:`.kits`): shapes are unions of up to six boxes, 2 cm high; the
    scene has five object bodies whose boxes take the episode's shapes (with the mass, 0.1 kg, and the inertia of
    a 6 x 6 cm slab); the kit and its slot marks are only seen, so an object put in a slot rests on the table, its
    top 1.5 cm over the kit's. Objects collide with the table and each other, but only the
    :data:`KITS_MAX_GEOM_PAIRS` nearest pairs of boxes of different objects go through collision detection at each
    physics step (MJX's broad phase).
    """
    count = kits.OBJECTS
    items = tuple(Item(f"object{i}", kits.OBJECT, kits.COLOURS[i]) for i in range(count)) + (Item("kit", kits.KIT),)
    symmetry = jnp.asarray(kits.SYMMETRY, jnp.float32)
    kit_footprint = tuple(x[:kits.KIT_TILES] for x in layout.shape_boxes(kits.KIT))  # its tiles cover it

    def geoms(scene):
        """The objects' boxes (object by object) and the kit's (tiles, then marks slot by slot)."""
        return np.flatnonzero(scene.geom_object < count), np.flatnonzero(scene.geom_object == count)

    def initialize(key, physics, held_out):
        object_geoms, kit_geoms = geoms(physics.scene)
        key_kit, key_shapes, key_slots, key_objects = jax.random.split(key, 4)
        kit_pos, kit_quat, _ = layout.random_pose(key_kit, layout.border(), kits.KIT_SIZE)
        low = jnp.where(held_out, kits.TEST_SHAPES[0], kits.TRAIN_SHAPES[0])
        high = jnp.where(held_out, kits.TEST_SHAPES[-1], kits.TRAIN_SHAPES[-1]) + 1
        shapes = jax.random.randint(key_shapes, (count,), low, high)
        slot_yaw = jax.random.uniform(key_slots, (count,), jnp.float32, 0.0, 2 * np.pi)
        kit_yaw = poses.yaw_of(kit_quat)
        offsets = jnp.concatenate([jnp.asarray(kits.SLOT_OFFSETS, jnp.float32), jnp.zeros((count, 1))], -1)
        slots = kit_pos + poses.rotate(kit_quat, offsets)
        targets = jnp.concatenate([slots[:, :2], jnp.full((count, 1), kits.HEIGHT / 2), slot_yaw[:, None]], -1)
        marks = kits.slot_marks(shapes, slot_yaw - kit_yaw)
        boxes = kits.object_boxes(shapes)
        taken = layout.border() | layout.footprint(kit_footprint, kit_pos, kit_quat)

        def spawn(taken, one):
            index, centres, half, yaw = one
            pos, quat, found = layout.random_pose(jax.random.fold_in(key_objects, index), taken, kits.EXTENT)
            covered = layout.footprint((centres, half, yaw), pos, quat)
            return taken | (covered & found), (pos, quat)

        _, (pos, quat) = jax.lax.scan(spawn, taken, (jnp.arange(count), *boxes))
        mark_geoms = kit_geoms[kits.KIT_TILES:]
        physics = physics.replace(
            geom_size=physics.geom_size.at[object_geoms].set(boxes[1].reshape(-1, 3)).at[mark_geoms].set(marks[1]),
            geom_pos=physics.geom_pos.at[object_geoms].set(boxes[0].reshape(-1, 3)).at[mark_geoms].set(marks[0]),
            geom_quat=physics.geom_quat.at[object_geoms].set(poses.yaw_quat(boxes[2]).reshape(-1, 4)).at[
                mark_geoms].set(poses.yaw_quat(marks[2])),
            queue=kits.Kitting(shapes=shapes.astype(jnp.int32), targets=targets))
        return place_objects(physics, jnp.concatenate([pos, kit_pos[None]]),
                             jnp.concatenate([quat, kit_quat[None]]))

    def goal(physics):
        shapes = physics.queue.shapes
        return Goal(objects=jnp.arange(count, dtype=jnp.int32), present=jnp.ones(count, bool),
                    symmetry=symmetry[shapes], targets=physics.queue.targets, target_present=jnp.ones(count, bool),
                    matches=shapes[:, None] == shapes[None, :])

    return RavenTask("assembling-kits", items, max_steps=10, pos_eps=0.01, initialize=initialize, goal=goal,
                     max_geom_pairs=KITS_MAX_GEOM_PAIRS, by_split=True)


TASKS: dict[str, Callable[[], RavenTask]] = {
    "block-insertion": block_insertion, "place-red-in-green": place_red_in_green,
    "align-box-corner": align_box_corner, "stack-block-pyramid": stack_block_pyramid,
    "towers-of-hanoi": towers_of_hanoi, "palletizing-boxes": palletizing_boxes,
    "packing-boxes": packing_boxes, "assembling-kits": assembling_kits}
"""Task name -> its factory."""
