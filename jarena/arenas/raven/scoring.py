"""Ravens' pose scoring: objects matched to target poses, in stages, with partial credit that sums to 1 per episode.

An object matches a target when its planar distance to it is under ``pos_eps`` (1 cm by default) and its heading
differs from the target's, modulo the object's rotational symmetry, by less than ``rot_eps`` (15 degrees); a
symmetry of 0 ignores the heading (Ravens' ``is_match``). A goal is a list of entries (an object and the targets it
may go to) in stages of given weights that add up to 1 (Ravens' list of goals: one stage for most tasks, the three
rows of a pyramid, the seven moves of the towers of Hanoi, where one object comes back in several stages). Only
the current stage is scored: its credit is its weight times the fraction of its entries that match one of their
targets (each entry counts once; as in Ravens, two objects on one target both count), or, for a goal with a
:class:`Zone` (Ravens' ``zone`` metric: palletizing), the share of its entries' points that lie in the zone's
rectangle, each object's points a 2 cm grid over its box (Ravens' ``get_object_points``). A stage is complete, its
weight banked for good and the next one scored, when its credit is within 0.01 of its weight with the objects at
rest (:func:`.physics.at_rest`: Ravens scores once the simulation is still). The score is the banked weights
plus the current stage's credit, and the reward is its change since the last step, so an episode's rewards add
up to its final score; the episode terminates when every stage is complete or the score passes 0.99. Success:
the score passes 0.99. The task runs after every control step of the cup; the pick-and-place tool adds up the
rewards of an action's steps and reports the rest as after its last one, where Ravens scores (after the objects
settle).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.raven import poses
from jarena.arenas.raven.physics import RavenPhysics, at_rest, object_poses
from jarena.core.task import Task
from jarena.core.tree import as_float32

ZONE_TOP = 0.3
"""Points higher than this above a zone's origin, metres, are not in it (Ravens' workspace top)."""
POINT_SPACING = 0.02
"""The spacing of an object's points for the zone metric, metres (Ravens' ``get_object_points``)."""


@struct.dataclass
class Zone:
    """A zone of the table that objects must cover (Ravens' ``zone`` metric).

    Attributes:
      pose: float32 (4,): the zone's ``(x, y, z, yaw)``.
      size: float32 (2,): its extents along its x and y axes, metres.
      points: float32 (O, P, 3): each goal entry's object's points, in the object's frame (Ravens' grid of 2 cm).
      valid: bool (O, P): which of them are points (objects with fewer are padded).
    """

    pose: jax.Array
    size: jax.Array
    points: jax.Array
    valid: jax.Array


@struct.dataclass
class Goal:
    """Where objects must go.

    Attributes:
      objects: int32 (O,): each entry's object (its index in the scene; an object may come in several entries).
      present: bool (O,): the entries that take part in this episode.
      symmetry: float32 (O,): each entry's object's rotational symmetry, radians (2 pi: none; 0: any heading).
      targets: float32 (T, 4): target poses ``(x, y, z, yaw)``.
      target_present: bool (T,): the targets of this episode.
      matches: bool (O, T): which targets each entry may go to.
      stage: int32 (O,): each entry's stage (``None``: one stage).
      weights: float32 (S,): each stage's share of the score, adding up to 1 (``None``: one stage, ``[1]``).
      zone: a :class:`Zone` scores the goal by the share of its present entries' points in the zone instead of
        by poses (one stage; the targets remain where the oracle puts the objects); ``None``: by poses.
    """

    objects: jax.Array
    present: jax.Array
    symmetry: jax.Array
    targets: jax.Array
    target_present: jax.Array
    matches: jax.Array
    stage: jax.Array | None = None
    weights: jax.Array | None = None
    zone: Zone | None = None


@struct.dataclass
class PoseGoalState:
    """The scoring task's state: the episode's :class:`Goal`, the reward handed out so far (the last score), the
    tolerances it is scored with (``pos_eps`` metres, ``rot_eps`` radians, from the params at reset), the current
    ``stage`` (int32 (), the number of stages complete) and the weights banked by them (``progress``)."""

    goal: Goal
    credited: jax.Array
    pos_eps: jax.Array
    rot_eps: jax.Array
    stage: jax.Array = 0
    progress: jax.Array = 0.0


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


def stages(goal: Goal) -> tuple[jax.Array, jax.Array]:
    """``(stage (O,), weights (S,))`` of a goal's entries (one stage of weight 1 where the goal names none)."""
    count = goal.objects.shape[0]
    stage = jnp.zeros(count, jnp.int32) if goal.stage is None else jnp.asarray(goal.stage, jnp.int32)
    weights = jnp.ones(1, jnp.float32) if goal.weights is None else jnp.asarray(goal.weights, jnp.float32)
    return stage, weights


def current_goal(goal: Goal, stage: jax.Array) -> Goal:
    """``goal`` with only the entries of ``stage`` present (none once every stage is complete)."""
    entry_stage, _ = stages(goal)
    return goal.replace(present=goal.present & (entry_stage == stage))


def in_zone(zone: Zone, pos: jax.Array, quat: jax.Array) -> jax.Array:
    """bool (O, P): which of the zone's points lie in it, with each entry's object at ``pos`` (O, 3), ``quat``
    (O, 4): inside the zone's rectangle (open bounds, as Ravens') and under :data:`ZONE_TOP` above its origin."""
    world = pos[:, None, :] + poses.rotate(quat[:, None, :], zone.points)
    local = poses.rotate(poses.yaw_quat(-zone.pose[3]), world - zone.pose[:3])
    half = zone.size / 2
    return (jnp.all(jnp.abs(local[..., :2]) < half, axis=-1) & (local[..., 2] < ZONE_TOP)) & zone.valid


def zone_fraction(planar: jax.Array, goal: Goal, quat: jax.Array | None = None) -> jax.Array:
    """float32 (): the share of the present entries' points that lie in the goal's zone (Ravens' zone metric: the
    points of all its objects counted together). ``planar`` (N, 4) every object's ``(x, y, z, yaw)``; ``quat``
    (N, 4) their orientations (``None``: upright, turned by their yaw)."""
    zone = goal.zone
    orientation = poses.yaw_quat(planar[:, 3]) if quat is None else quat
    inside = in_zone(zone, planar[goal.objects, :3], orientation[goal.objects])
    counted = zone.valid & goal.present[:, None]
    return jnp.sum(inside & counted) / jnp.maximum(jnp.sum(counted), 1)


def stage_credit(planar: jax.Array, goal: Goal, stage: jax.Array, params: PoseGoalParams,
                 quat: jax.Array | None = None) -> jax.Array:
    """float32 (): the credit of ``stage``: its weight times the fraction of its present entries that match an
    allowed target, or for a goal with a zone the share of their points in it (0 past the last stage); ``quat``
    (N, 4) the objects' orientations for a zone (``None``: upright at their yaw)."""
    _, weights = stages(goal)
    mine = current_goal(goal, stage)
    if goal.zone is not None:
        fraction = zone_fraction(planar, mine, quat)
    else:
        placed = jnp.any(matched(planar, mine, params), axis=-1)
        fraction = jnp.sum(placed) / jnp.maximum(jnp.sum(mine.present), 1)
    return jnp.where(stage < weights.shape[0], weights[jnp.minimum(stage, weights.shape[0] - 1)] * fraction, 0.0)


def score(planar: jax.Array, goal: Goal, params: PoseGoalParams, stage: jax.Array = 0,
          progress: jax.Array = 0.0, quat: jax.Array | None = None) -> jax.Array:
    """float32 (): the score with ``stage`` current and ``progress`` banked: ``progress`` plus the stage's credit
    (for a goal of one stage, from its start: the fraction of the present objects that match an allowed
    target, or the share of their points in the goal's zone; ``quat`` as for :func:`stage_credit`)."""
    return progress + stage_credit(planar, goal, jnp.asarray(stage, jnp.int32), params, quat)


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
    ``info.goal`` holds the targets, float32 (T x 4,). Metrics: ``placed`` (the score), ``stages`` (the number of
    stages complete), the errors of the current stage's entries (the last stage's once all are complete).
    """

    def measure(physics, state, params):
        planar = planar_poses(physics)
        quat = object_poses(physics)[1] if state.goal.zone is not None else None
        credit = stage_credit(planar, state.goal, state.stage, params, quat)
        _, weights = stages(state.goal)
        scored = current_goal(state.goal, jnp.minimum(state.stage, weights.shape[0] - 1))
        return credit, planar, {**errors(planar, scored), "grasp_slip": physics.slip}

    def reset(key, physics, outcome, params):
        goal = goal_of(physics)
        state = PoseGoalState(goal=goal, credited=jnp.zeros((), jnp.float32), pos_eps=params.pos_eps,
                              rot_eps=params.rot_eps, stage=jnp.zeros((), jnp.int32),
                              progress=jnp.zeros((), jnp.float32))
        now, _, metrics = measure(physics, state, params)
        metrics = dict(metrics, placed=now, stages=jnp.zeros((), jnp.float32))
        return outcome.replace(goal=goal.targets.reshape(-1), reward_terms=dict(outcome.reward_terms, placed=now),
                               metrics=dict(outcome.metrics, **metrics, total_reward=state.credited)), state

    def update(state, outcome, transition, params):
        credit, _, metrics = measure(transition.physics, state, params)
        _, weights = stages(state.goal)
        now = state.progress + credit
        weight = weights[jnp.minimum(state.stage, weights.shape[0] - 1)]
        complete = (state.stage < weights.shape[0]) & (jnp.abs(weight - credit) < 0.01) & at_rest(
            transition.physics)
        stage = state.stage + complete.astype(jnp.int32)
        done = (stage >= weights.shape[0]) | (now > 0.99)
        previous = state.credited
        state = state.replace(credited=now, stage=stage, progress=state.progress + jnp.where(complete, weight, 0.0))
        metrics = dict(metrics, placed=now, stages=stage.astype(jnp.float32))
        return outcome.replace(reward=outcome.reward + (now - previous), terminated=outcome.terminated | done,
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
