"""Checks shared by the agents that train from a :class:`jarena.data.TrajectoryDataset`.

For those that read a dataset whole onto the device and draw from it inside their compiled updates (``bc``,
``diffusion``, ``transporter``, offline ``planet``): :func:`to_device`; and :func:`read_steps` and
:func:`sample_windows` (offline ``planet``).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.arena import Arena
from jarena.data import DatasetError, TrajectoryDataset, configs_for
from jarena.data.loader import draw_indices, gather_device
from jarena.data.schema import STEP_FIELDS

PyTree = Any

#: The dataset groups and the arena config each must equal.
GROUPS = {"observation": "obs_config", "action": "act_config", "goal": "goal_config"}


def check_dataset(dataset: TrajectoryDataset, arena: Arena, agent: str,
                  groups: tuple[str, ...] = ("observation", "action", "goal"), need: str = "trajectories") -> None:
    """Raises a ``DatasetError`` naming ``agent`` unless ``dataset``'s ``groups`` hold ``arena``'s fields (shape and
    dtype) and it has at least one of ``need`` (``trajectories`` or ``steps``)."""
    expected = configs_for(arena)
    problems = []
    for group in groups:
        have = {n: (tuple(f.shape), f.dtype) for n, f in getattr(dataset.schema, group).items()}
        want = {n: (tuple(f.shape), f.dtype) for n, f in expected[GROUPS[group]].items()}
        if have != want:
            problems.append(f"{group} fields (shape, dtype) {have}, the arena's {want}")
    if problems:
        raise DatasetError(f"{agent}: the dataset at {dataset.path!r} does not fit arena {arena.name!r}: "
                           + "; ".join(problems))
    count = dataset.num_steps() if need == "steps" else dataset.num_trajectories()
    if count == 0:
        raise DatasetError(f"{agent}: the dataset at {dataset.path!r} has no {need}")


def read_steps(path: str, arena: Arena, agent: str) -> dict[str, Any]:
    """The whole dataset at ``path``, checked against ``arena`` (:func:`check_dataset`), as numpy arrays in its
    stored layout, fields keyed by their names (the arena's keys, which :func:`check_dataset` matched).

    Returns a dict: ``observation`` (dict of (sum T_i + N, ...): each trajectory's T_i + 1 observations end to
    end), ``action`` (dict of (sum T_i, ...)), ``goal`` (dict of (N, ...)), ``reward`` float32, ``terminated`` and
    ``truncated`` bool (sum T_i,), and ``lengths`` int32 (N,), the T_i.
    """
    with TrajectoryDataset(path, "r") as dataset:
        check_dataset(dataset, arena, agent)
        n, steps = dataset.num_trajectories(), dataset.num_steps()
        rows = {"observation": steps + n, "action": steps, "goal": n}
        out: dict[str, Any] = {group: {name: dataset.rows(f"{group}/{name}", 0, rows[group])
                                       for name in getattr(dataset.schema, group)} for group in rows}
        out.update({name: dataset.rows(f"step/{name}", 0, steps) for name in STEP_FIELDS})
        out["lengths"] = dataset.lengths().astype(np.int32)
    return out


def to_device(host: PyTree) -> PyTree:
    """``host`` (numpy leaves) as traced values fetched by a host callback, not embedded as constants: for a
    ``jit``-ed ``init_training`` that puts a dataset in its train state."""
    shapes = jax.tree_util.tree_map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype), host)
    return jax.pure_callback(lambda: host, shapes)


def sample_windows(data: dict, key: jax.Array, batch_size: int, length: int) -> dict[str, Any]:
    """``batch_size`` windows of ``length`` consecutive steps, each inside one trajectory, drawn uniformly among all
    such windows (:func:`jarena.data.loader.draw_indices`) from ``data`` laid out as :func:`read_steps` gives it
    (on device; jittable).

    Returns the batch of a :class:`jarena.data.Loader` in ``mode="window"`` drawn with the same key, leaves (S, L,
    ...): ``observation`` and ``next_observation`` (dicts), ``action`` and ``goal`` (dicts; the goal repeated per
    step), ``reward``, ``terminated``, ``truncated``, ``mask`` (all true), ``first`` / ``last`` (the step starts /
    ends its trajectory), ``trajectory`` and ``step``.
    """
    lengths = jnp.asarray(data["lengths"])
    flat = {f"{group}/{name}": data[group][name] for group in GROUPS for name in data[group]}
    flat.update({f"step/{name}": data[name] for name in STEP_FIELDS})
    layout = tuple((*name.split("/")[:1], name, name.split("/")[1]) for name in flat)  # the batch keyed by name
    rank, step, mask = draw_indices(key, lengths, "window", batch_size, length)
    return gather_device(flat, rank, step, mask, lengths, jnp.arange(lengths.size, dtype=jnp.int32), layout)
