"""Diffusion Policy's data: demonstrations read whole from a TrajectoryDataset, normalised to [-1, 1] from their
limits, and padded windows of H steps drawn from them.

A training sample is a window of ``H`` consecutive steps of one trajectory: the observations of its first ``T_o``
steps (the condition) and all ``H`` actions (what is generated), action ``k`` taken at the window's step ``k``.
Windows may start up to ``T_o - 1`` steps before a trajectory's first step and end up to ``T_a - 1`` steps after its
last; the missing steps repeat the first observation and action, or the last action (Diffusion Policy's sequence
padding), so that every step of every trajectory is seen at every position of the window that acting uses.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.core.arena import Arena
from jarena.data.loader import draw_indices
from jarena.data.schema import DatasetError
from jarena_agents.datasets import read_steps

RANGE_EPSILON = 1e-4  # a dimension whose values span less is constant: it normalises to 0


@struct.dataclass
class Limits:
    """Per-dimension limits of a float32 (..., D) quantity: ``low``, ``high`` (D,). :func:`to_unit` maps
    ``[low, high]`` linearly onto [-1, 1] (Diffusion Policy's ``LinearNormalizer`` in its ``limits`` mode)."""

    low: jax.Array
    high: jax.Array


@struct.dataclass
class Normalizer:
    """The limits of the flat action vectors (A,) and of the low-dimensional observation vectors (D,)."""

    action: Limits
    vector: Limits


def _scale_offset(limits: Limits) -> tuple[jax.Array, jax.Array]:
    span = limits.high - limits.low
    constant = span < RANGE_EPSILON
    scale = jnp.where(constant, 1.0, 2.0 / jnp.where(constant, 1.0, span))
    offset = jnp.where(constant, -limits.low, -1.0 - scale * limits.low)
    return scale, offset


def to_unit(limits: Limits, x: jax.Array) -> jax.Array:
    """float (..., D) -> float32 (..., D): ``low`` to -1, ``high`` to 1; a constant dimension (span below 1e-4) to 0."""
    scale, offset = _scale_offset(limits)
    return x.astype(jnp.float32) * scale + offset


def from_unit(limits: Limits, y: jax.Array) -> jax.Array:
    """The inverse of :func:`to_unit`."""
    scale, offset = _scale_offset(limits)
    return (y - offset) / scale


def limits_of(rows: np.ndarray) -> Limits:
    """The limits of float (N, D) rows (N >= 1)."""
    return Limits(low=rows.min(0).astype(np.float32), high=rows.max(0).astype(np.float32))


def flatten(observation: dict, goal: dict, images: tuple[str, ...], lead: tuple[int, ...]) -> dict:
    """Observations with sample axes ``lead`` (e.g. (S, T_o)) as the networks' input: ``{"vector": float32
    (*lead, D), "images": {key: observation[key]}}``. The vector joins the fields but ``images`` (sorted by name)
    then the goal's (leaves (lead[0], ...), repeated along the other sample axes), each flattened: the same vector
    as :func:`jarena_agents.networks.split_observation` gives for an ``Info``."""
    rest = [v.reshape(lead + (-1,)) for k, v in sorted(observation.items()) if k not in images]
    ones = (1,) * (len(lead) - 1)
    goals = [jnp.broadcast_to(g.reshape(lead[:1] + ones + (-1,)), lead + (int(np.prod(g.shape[1:], dtype=int)),))
             for g in jax.tree_util.tree_leaves(goal)]
    vector = jnp.concatenate([jnp.zeros(lead + (0,), jnp.float32)] + [x.astype(jnp.float32) for x in rest + goals],
                             axis=-1)
    return {"vector": vector, "images": {k: observation[k] for k in images}}


def shortest_useful(horizon: int, obs_horizon: int, action_steps: int) -> int:
    """The fewest steps a trajectory needs to hold one padded window."""
    return max(1, horizon - (obs_horizon - 1) - (action_steps - 1))


def read_dataset(path: str, arena: Arena, images: tuple[str, ...], horizon: int, obs_horizon: int,
                 action_steps: int) -> dict[str, Any]:
    """The whole dataset at ``path`` as numpy arrays and its limits.

    Returns a dict: ``data`` (``observation``: dict of (sum T_i + 1, ...), each trajectory's T_i + 1 observations
    end to end; ``action``: (sum T_i, A) flat; ``goal``: dict of (N, ...)), ``lengths`` int32 (N,) (the T_i) and
    ``action_limits`` / ``vector_limits`` (:class:`Limits` over every action, and over every observation's
    low-dimensional vector, ``images`` left out).
    """
    if not path:
        raise ValueError("diffusion needs demonstrations: set its config key dataset=PATH to a TrajectoryDataset "
                         "(collect one with `jarena collect AGENT ARENA --out PATH`)")
    read = read_steps(path, arena, "diffusion")
    lengths = read["lengths"]
    needed = shortest_useful(horizon, obs_horizon, action_steps)
    if lengths.max() < needed:
        raise DatasetError(f"diffusion: horizon={horizon} with obs_horizon={obs_horizon} and "
                           f"action_steps={action_steps} needs trajectories of at least {needed} steps; the "
                           f"longest in {path!r} has {lengths.max()}")
    n, steps = len(lengths), int(lengths.sum())
    observation, goal = read["observation"], read["goal"]
    (action,) = read["action"].values()
    action = action.reshape(steps, -1)
    row_goal = {k: np.repeat(v, lengths + 1, axis=0) for k, v in goal.items()}
    rest = [v for k, v in sorted(observation.items()) if k not in images]
    vectors = np.concatenate([np.zeros((steps + n, 0), np.float32)]
                             + [x.reshape(steps + n, -1).astype(np.float32)
                                for x in rest + jax.tree_util.tree_leaves(row_goal)], axis=-1)
    return dict(data=dict(observation=observation, action=action, goal=goal), lengths=lengths.astype(np.int32),
                action_limits=limits_of(action), vector_limits=limits_of(vectors))


def sample_windows(data: dict, lengths: jax.Array, key: jax.Array, batch_size: int, horizon: int, obs_horizon: int,
                   action_steps: int) -> tuple[dict, dict, jax.Array]:
    """A minibatch of padded windows, drawn uniformly among every start (see the module docstring) with
    :func:`jarena.data.loader.draw_indices` over the padded lengths.

    Returns ``(observation, goal, actions)``: the first ``obs_horizon`` observations of each window (dict of
    (S, T_o, ...)), its trajectory's goal (dict of (S, ...)) and its ``horizon`` actions ((S, H, A)).
    """
    before, after = obs_horizon - 1, action_steps - 1
    rank, step, _ = draw_indices(key, lengths + before + after, "window", batch_size, horizon)
    length = lengths[rank[:, 0]][:, None]
    step = jnp.clip(step - before, 0, length - 1)  # (S, H): padding repeats the first and last steps
    first_action = (jnp.cumsum(lengths) - lengths)[rank[:, 0]][:, None]  # trajectory i's first action row
    observation_rows = first_action + rank[:, :1] + step[:, :obs_horizon]  # its observations start i rows later
    observation = {k: v[observation_rows] for k, v in data["observation"].items()}
    goal = {k: v[rank[:, 0]] for k, v in data["goal"].items()}
    return observation, goal, data["action"][first_action + step]
