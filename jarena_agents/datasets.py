"""Checks shared by the agents that train from a :class:`jarena.data.TrajectoryDataset`."""

from __future__ import annotations

from jarena.core.arena import Arena
from jarena.data import DatasetError, TrajectoryDataset, configs_for

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
