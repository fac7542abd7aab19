"""Ravens' tasks: each names its objects, lays out an episode and sets its goal (``ravens/tasks/*.py``)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.raven import layout
from jarena.arenas.raven.physics import RavenPhysics, place_objects
from jarena.arenas.raven.scene import ELL, FIXTURE, Item
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


def block_insertion() -> RavenTask:
    """Ravens' ``block-insertion``: put the L-shaped block into the L-shaped fixture, in its pose (the L has no
    symmetry: 2 pi). Both are placed at random in free space, the block first; 3 actions."""
    items = (Item("ell", ELL), Item("fixture", FIXTURE))

    def initialize(key, physics):
        pos, quat, _, _ = layout.place_in_turn(key, (ELL, FIXTURE))
        return place_objects(physics, pos, quat)

    def goal(physics):
        fixture = planar_poses(physics)[1]
        return Goal(objects=jnp.asarray([0], jnp.int32), present=jnp.ones((1,), bool),
                    symmetry=jnp.asarray([2 * np.pi], jnp.float32), targets=fixture[None],
                    target_present=jnp.ones((1,), bool), matches=jnp.ones((1, 1), bool))

    return RavenTask("block-insertion", items, max_steps=3, pos_eps=0.01, initialize=initialize, goal=goal)


TASKS: dict[str, Callable[[], RavenTask]] = {"block-insertion": block_insertion}
"""Task name -> its factory."""
