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

from jarena.arenas.raven import layout, poses
from jarena.arenas.raven import scene as shapes
from jarena.arenas.raven.heightmap import BOUNDS
from jarena.arenas.raven.physics import RavenPhysics, object_poses, place_objects
from jarena.arenas.raven.scene import BLOCK, Item, rgb
from jarena.arenas.raven.scoring import Goal, planar_poses


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
    """

    name: str
    items: tuple[Item, ...]
    max_steps: int
    pos_eps: float
    initialize: Callable[[jax.Array, RavenPhysics], RavenPhysics]
    goal: Callable[[RavenPhysics], Goal]


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


TASKS: dict[str, Callable[[], RavenTask]] = {
    "block-insertion": block_insertion, "place-red-in-green": place_red_in_green,
    "align-box-corner": align_box_corner, "stack-block-pyramid": stack_block_pyramid,
    "towers-of-hanoi": towers_of_hanoi}
"""Task name -> its factory."""
