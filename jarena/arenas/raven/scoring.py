"""Ravens' pose scoring: objects matched to target poses, with partial credit that sums to 1 per episode.

An object matches a target when its planar distance to it is under ``pos_eps`` (1 cm by default) and its heading
differs from the target's, modulo the object's rotational symmetry, by less than ``rot_eps`` (15 degrees); a
symmetry of 0 ignores the heading (Ravens' ``is_match``). Each step the score is the fraction of objects that
match one of the targets they may go to (each object counts once; as in Ravens, two objects on one target both
count). The reward is the score's change since the last step, so an episode's rewards add up to its final
score; once every object matches (the score within 0.01 of 1) the goal is complete and the episode terminates.
Success: the rewards so far add up to more than 0.99. The task runs after every control step of the cup; the
pick-and-place tool adds up the rewards of an action's steps and reports the rest as after its last one, where
Ravens scores (after the objects settle).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.raven import poses
from jarena.arenas.raven.physics import RavenPhysics, object_poses
from jarena.core.task import Task
from jarena.core.tree import as_float32


@struct.dataclass
class Goal:
    """Where objects must go.

    Attributes:
      objects: int32 (O,): the objects to place (their index in the scene).
      present: bool (O,): those that take part in this episode.
      symmetry: float32 (O,): each object's rotational symmetry, radians (2 pi: none; 0: any heading).
      targets: float32 (T, 4): target poses ``(x, y, z, yaw)``.
      target_present: bool (T,): the targets of this episode.
      matches: bool (O, T): which targets each object may go to.
    """

    objects: jax.Array
    present: jax.Array
    symmetry: jax.Array
    targets: jax.Array
    target_present: jax.Array
    matches: jax.Array


@struct.dataclass
class PoseGoalState:
    """The scoring task's state: the episode's :class:`Goal`, the reward handed out so far (the last score), and
    the tolerances it is scored with (``pos_eps`` metres, ``rot_eps`` radians, from the params at reset)."""

    goal: Goal
    credited: jax.Array
    pos_eps: jax.Array
    rot_eps: jax.Array


@struct.dataclass
class PoseGoalParams:
    """``pos_eps``: metres; ``rot_eps``: radians (Ravens' defaults 1 cm and 15 degrees)."""

    pos_eps: jax.Array = 0.01
    rot_eps: jax.Array = float(np.deg2rad(15.0))


def heading_error(yaw: jax.Array, target_yaw: jax.Array, symmetry: jax.Array) -> jax.Array:
    """Radians between two headings modulo ``symmetry`` (0 where the symmetry is 0: any heading)."""
    period = jnp.where(symmetry > 0, symmetry, 1.0)
    difference = jnp.mod(jnp.abs(yaw - target_yaw), period)
    return jnp.where(symmetry > 0, jnp.minimum(difference, period - difference), 0.0)


def match_errors(planar: jax.Array, goal: Goal) -> tuple[jax.Array, jax.Array]:
    """``(distance, heading)``, float32 (O, T): each object's planar distance (metres) and heading error (radians,
    modulo its symmetry) to each target; ``planar`` (N, 4) every object's ``(x, y, z, yaw)``."""
    mine = planar[goal.objects]
    distance = jnp.linalg.norm(mine[:, None, :2] - goal.targets[None, :, :2], axis=-1)
    heading = heading_error(mine[:, None, 3], goal.targets[None, :, 3], goal.symmetry[:, None])
    return distance, heading


def matched(planar: jax.Array, goal: Goal, params: PoseGoalParams) -> jax.Array:
    """bool (O, T): which allowed object-target pairs match."""
    distance, heading = match_errors(planar, goal)
    allowed = goal.matches & goal.target_present[None, :] & goal.present[:, None]
    return allowed & (distance < params.pos_eps) & (heading < params.rot_eps)


def score(planar: jax.Array, goal: Goal, params: PoseGoalParams) -> jax.Array:
    """float32 (): the fraction of the present objects that match an allowed target."""
    placed = jnp.any(matched(planar, goal, params), axis=-1)
    return jnp.sum(placed) / jnp.maximum(jnp.sum(goal.present), 1)


def errors(planar: jax.Array, goal: Goal) -> dict[str, jax.Array]:
    """Mean over present objects of the planar distance (m) to the nearest allowed target, and the heading error
    (rad) to that target."""
    distance, heading = match_errors(planar, goal)
    allowed = goal.matches & goal.target_present[None, :]
    distance = jnp.where(allowed, distance, jnp.inf)
    nearest = jnp.argmin(distance, axis=-1)
    rows = jnp.arange(distance.shape[0])
    weight = goal.present / jnp.maximum(jnp.sum(goal.present), 1)
    has_target = jnp.any(allowed, axis=-1)
    return {"position_error": jnp.sum(jnp.where(has_target, distance[rows, nearest], 0.0) * weight),
            "rotation_error": jnp.sum(jnp.where(has_target, heading[rows, nearest], 0.0) * weight)}


def planar_poses(physics: RavenPhysics) -> jax.Array:
    """float32 (N, 4): every object's ``(x, y, z, yaw)``."""
    return poses.planar(*object_poses(physics))


def pose_goal(goal_of: Callable[[RavenPhysics], Goal], name: str, pos_eps: float = 0.01,
              initialize: Callable[[jax.Array, RavenPhysics], RavenPhysics] | None = None) -> Task:
    """The scoring task (module docstring) of the goal ``goal_of(physics)`` set at reset.

    ``initialize(key, physics) -> physics`` lays out the episode's objects (the task's ``initialize``).

    Reward terms: ``placed`` (the score). Metrics: ``placed``, ``total_reward`` (rewards so far), :func:`errors`,
    and ``grasp_slip``, metres (``RavenPhysics.slip``: how far the last held object strayed from the cup's grasp).
    ``info.goal`` holds the targets, float32 (T x 4,).
    """

    def measure(physics, state, params):
        planar = planar_poses(physics)
        now = score(planar, state.goal, params)
        return now, {"placed": now, **errors(planar, state.goal), "grasp_slip": physics.slip}

    def reset(key, physics, outcome, params):
        goal = goal_of(physics)
        state = PoseGoalState(goal=goal, credited=jnp.zeros((), jnp.float32), pos_eps=params.pos_eps,
                              rot_eps=params.rot_eps)
        now, metrics = measure(physics, state, params)
        return outcome.replace(goal=goal.targets.reshape(-1), reward_terms=dict(outcome.reward_terms, placed=now),
                               metrics=dict(outcome.metrics, **metrics, total_reward=state.credited)), state

    def update(state, outcome, transition, params):
        now, metrics = measure(transition.physics, state, params)
        credited = state.credited
        complete = jnp.abs(1.0 - now) < 0.01
        state = state.replace(credited=now)
        return outcome.replace(reward=outcome.reward + (now - credited), terminated=outcome.terminated | complete,
                               success=now > 0.99, goal=state.goal.targets.reshape(-1),
                               reward_terms=dict(outcome.reward_terms, placed=now),
                               metrics=dict(outcome.metrics, **metrics, total_reward=now)), state

    extra = {}
    if initialize is not None:
        extra["initialize"] = lambda key, physics, dynamics_params, params: initialize(key, physics)
    return Task(update=update, reset=reset, default_params=lambda: as_float32(PoseGoalParams(pos_eps=pos_eps)),
                name=name, has_success=True, **extra)


def goal_state(task_state) -> PoseGoalState | None:
    """The :class:`PoseGoalState` in an arena's task state (a chain's tuple), or ``None``."""
    if isinstance(task_state, PoseGoalState):
        return task_state
    if isinstance(task_state, tuple | list):
        for s in task_state:
            found = goal_state(s)
            if found is not None:
                return found
    return None
